"""Rates of a particle's state under the basis columns a scene selects, in few tensor ops.

The right-hand side of VG-TRAJ (spec/motion.md: VG-VEL and VG-ROTSCALE, with the column
masks of VG-BASIS). Columns outside the mask have w_j = 0, so a part of the state that only
they drive is constant and left out of the integration:
- no rotation column: q_dot = 1/2 (0, omega) (x) q = 0, so q stays q0;
- no stretch or shear column: the rate of strain D is 0, so log s stays log s0 and R(q) is
  never needed.
The rest of the state is y = [x (3) | q (4, with rotation) | log s (3, with stretch or shear)].
The rates of x and q are linear in (x, 1, q) with a matrix linear in w (`generators`), and
each group of active columns adds one term: translation T_t @ b, rotation
T_r @ (omega (x) [x; q]), stretch and shear T_s @ (w_s (x) x): an outer product of only the
coefficients and state rows that meet, and one matrix product (an addmm). log s has rate
diag(R^T D R) with D = E @ w_s (the spin part of grad v adds 0 on every axis).

Every tensor here is component-major, (components, N): one contiguous row of N particles
per component. Elementwise products then run over long rows and the matrix products have N
columns, where (N, components) would broadcast over rows of 3 to 8 entries (measured 3 to
10 times slower per op on CPU for N in the thousands). The kernels take no validity checks
(they run once per integration stage); the checked callers are `rotscale_rates` and
`base_state`.
"""

from typing import NamedTuple

import numpy as np
import torch

from velogauss_fast.motion.generators import SLOTS, block_generator, rotmat_form, strain_generator
from velogauss_core.constants import QUAT_ZERO_NORM_SQ
from velogauss_core.motion import COLUMN_GROUPS
from velogauss_core.motion import N_BASIS

# Column groups in VG-BASIS order, so a mask's active columns, ascending, come group by group.
GROUP_COLUMNS = {
    "translation": COLUMN_GROUPS["translation"],
    "rotation": COLUMN_GROUPS["rotation"],
    "strain": COLUMN_GROUPS["stretch"] + COLUMN_GROUPS["shear"],
}
# The state slots each group's columns act on: translation adds b(w) (the constant "1"),
# rotation turns x and q, stretch and shear deform x.
READS = {"translation": ("1",), "rotation": ("x", "q"), "strain": ("x",)}


class Layout(NamedTuple):
    """The active columns of a mask, ascending (translation, rotation, then stretch and shear),
    and how many of them fall in each group of GROUP_COLUMNS (`sizes`, in that order)."""

    columns: tuple
    sizes: tuple

    @property
    def rotation(self):
        return self.sizes[1] > 0

    @property
    def strain(self):
        return self.sizes[2] > 0

    @property
    def width(self):
        """Rows of the state before log s: x (3), and q (4) with rotation."""
        return 3 + 4 * self.rotation


class RatePlan(NamedTuple):
    """A Layout with its constant tensors in one dtype and device.

    blocks: one (group index, T, rows read) per group with active columns: T from
    `block_generator` onto the rows [x; q] (or [x]), the state rows the group reads (0 for
    translation, whose term is b itself; 3 for x; 7 for x and q); E: `strain_generator` of
    the active stretch and shear columns.
    """

    layout: Layout
    blocks: tuple
    E: torch.Tensor


def layout(mask):
    """The Layout of a column mask (cfg.mask: None for all 12 columns, or 12 bools)."""
    active = np.ones(N_BASIS, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    sizes = tuple(int(active[list(cols)].sum()) for cols in GROUP_COLUMNS.values())
    return Layout(tuple(int(j) for j in np.flatnonzero(active)), sizes)


def rate_plan(mask, dtype, device):
    """The RatePlan of a column mask (cfg.mask) for tensors of `dtype` on `device`."""
    lay = layout(mask)
    outputs = ("x", "q") if lay.rotation else ("x",)
    bounds = np.cumsum((0,) + lay.sizes)
    blocks = []
    for k, group in enumerate(GROUP_COLUMNS):
        if lay.sizes[k]:
            T = block_generator(lay.columns[bounds[k]:bounds[k + 1]], READS[group], outputs, dtype, device)
            blocks.append((k, T, sum(len(SLOTS[part]) for part in READS[group] if part != "1")))
    return RatePlan(lay, tuple(blocks), strain_generator(lay.columns[bounds[2]:], dtype, device))


def state_rates(plan, w, y, RR=None):
    """dy/dt (rows, N) of the state y (rows, N) laid out by plan.layout, for the active
    coefficients w (a, N) (VG-TRAJ's right-hand side; plan.layout must have a column).

    RR: `axis_products` of the constant R(q0) when log s is integrated but q is not; None
    otherwise (R(q) is then rebuilt from the state's q).
    """
    lay = plan.layout
    w_groups = w.split(lay.sizes)
    xq = y[:lay.width] if lay.strain else y
    rates = None
    for k, T, n_read in plan.blocks:
        term = w_groups[k] if n_read == 0 else outer(w_groups[k], xq[:n_read])
        rates = T @ term if rates is None else torch.addmm(rates, T, term)
    if not lay.strain:
        return rates
    if RR is None:
        RR = axis_products(rotmat(xq[3:7]))
    return torch.cat([rates, strain_rates(w_groups[2], RR, plan.E)])


def outer(w, v):
    """Every product w_j v_k of w (a, N) and v (r, N), as (a r, N) with row j r + k."""
    return (w[:, None, :] * v[None, :, :]).reshape(w.shape[0] * v.shape[0], w.shape[1])


def rotmat(q):
    """R(q / |q|) row-major: q (4, N) of any norm -> (9, N) (VG-QUAT).

    One quadratic form (`generators.rotmat_form`) gives |q|^2 R and |q|^2; below
    QUAT_ZERO_NORM_SQ the result is the identity with zero gradient (the division sees 1,
    not ~0, so neither pass produces NaN).
    """
    R_scaled, n2 = (rotmat_form(q.dtype, q.device) @ outer(q, q)).split([9, 1])
    zero = n2 < QUAT_ZERO_NORM_SQ
    identity = torch.eye(3, dtype=q.dtype, device=q.device).reshape(9, 1)
    return torch.where(zero, identity, R_scaled / torch.where(zero, 1.0, n2))


def axis_products(R):
    """RR (9, 3, N), RR[3 i + k, a] = R_ia R_ka, for R (9, N) row-major: the products that the
    strain rate along principal axis a (column a of R) combines."""
    R3 = R.reshape(3, 3, R.shape[1])
    return (R3[:, None, :, :] * R3[None, :, :, :]).reshape(9, 3, R.shape[1])


def strain_rates(w_strain, RR, E):
    """d log s / dt = diag(R^T D R) (3, N) with D = E @ w_strain (VG-ROTSCALE).

    w_strain: (a, N) stretch and shear coefficients; RR: (9, 3, N) from `axis_products`;
    E: (9, a) from `strain_generator`.
    """
    return ((E @ w_strain)[:, None, :] * RR).sum(0)
