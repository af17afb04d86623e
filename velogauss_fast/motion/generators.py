"""Constant tensors that turn the particle rates of VG-TRAJ into a few matrix products.

spec/motion.md, VG-BASIS, VG-ROTSCALE; spec/rendering.md, VG-QUAT. Every table here is
derived from the spec functions themselves (`affine_from_coefficients` of VG-BASIS,
`quat_multiply` of VG-QUAT-MUL) applied to unit vectors, never written out by hand, so it
cannot drift from them.

The linear part of a particle's state is u = [x (3) | 1 | q (4)] (the slots below). Its
rates are linear in u with a matrix linear in the coefficients w (VG-VEL, VG-ROTSCALE):

    du/dt = sum_j w_j G_j u,   G_j = [[A(e_j), b(e_j), 0], [0, 0, 0], [0, 0, Q_j]],

(A(e_j), b(e_j)) being VG-BASIS's affine form of the j-th unit coefficient vector and
Q_j q = 1/2 (0, omega(e_j)) (x) q. The constant slot "1" carries the translation b(w).
"""

import functools

import torch

from velogauss_fast.motion.basis import affine_from_coefficients
from velogauss_fast.quaternion import quat_multiply
from velogauss_core.motion import COLUMN_GROUPS
from velogauss_core.motion import N_BASIS

# Positions of the parts of u = [x | 1 | q] in the full generators.
SLOTS = {"x": (0, 1, 2), "1": (3,), "q": (4, 5, 6, 7)}


@functools.lru_cache(maxsize=None)
def block_generator(columns, reads, outputs, dtype, device):
    """T (m, a r): the rates of the `outputs` slots driven by `columns` acting on the `reads` slots.

    columns: tuple of a VG-BASIS columns; reads, outputs: tuples of slot names (SLOTS), r and
    m entries in all. Entry (i, j r + k) of T is G_j[outputs[i], reads[k]], so with w (a, N)
    and the read rows v (r, N) stored one row per component,
    T @ (w[:, None] * v[None]).reshape(a r, N) is sum_j w_j G_j v on the output rows. With
    reads = ("1",) the product is w itself: T @ w. Cached per argument tuple; never modified.
    """
    rows = [i for part in outputs for i in SLOTS[part]]
    cols = [i for part in reads for i in SLOTS[part]]
    G = _full_generators()[list(columns)][:, rows][:, :, cols]  # [a, m, r]
    return G.transpose(0, 1).reshape(len(rows), len(columns) * len(cols)).contiguous().to(dtype=dtype, device=device)


@functools.lru_cache(maxsize=None)
def strain_generator(columns, dtype, device):
    """E (9, a): column j is D(e_j) = (A(e_j) + A(e_j)^T) / 2 flattened row-major (VG-ROTSCALE).

    D = E @ w_s is the rate of strain, one row per entry, of the coefficients w_s (a, N) of
    `columns`. The rotation columns' D(e_j) is zero (their A is antisymmetric), so only
    stretch and shear columns need be passed. Cached; never modified.
    """
    A, _ = affine_from_coefficients(torch.eye(N_BASIS, dtype=torch.float64)[list(columns)])
    return (0.5 * (A + A.transpose(1, 2))).reshape(len(columns), 9).T.contiguous().to(dtype=dtype, device=device)


@functools.lru_cache(maxsize=None)
def rotmat_form(dtype, device):
    """C (10, 16): C @ (q (x) q) = [|q|^2 R(q / |q|) row-major (9) | |q|^2] (VG-QUAT).

    q (4, N) one row per component, q (x) q reshaped (16, N). R(q) v = q (x) (0, v) (x) conj(q)
    for a unit q, so column a of |q|^2 R is sum_kl q_k q_l vec(e_k (x) (0, e_a) (x) conj(e_l)):
    a quadratic form whose coefficients are Hamilton products of unit quaternions. Cached;
    never modified.
    """
    units = torch.eye(4, dtype=torch.float64)
    axes = units[1:]  # (0, e_a), a = 0..2
    conj = units * torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=torch.float64)
    # [k, l, a, :] = e_k (x) (0, e_a) (x) conj(e_l); its vector part is column a of R's form.
    prod = quat_multiply(quat_multiply(units[:, None, None, :], axes[None, None, :, :]), conj[None, :, None, :])
    R_form = prod[..., 1:].transpose(2, 3).reshape(16, 9)  # rows (k, l), columns (row i, column a) of R
    return torch.cat([R_form, units.reshape(16, 1)], dim=1).T.contiguous().to(dtype=dtype, device=device)


@functools.lru_cache(maxsize=1)
def _full_generators():
    """G (12, 8, 8) in float64: G_j acting on u = [x | 1 | q], for every VG-BASIS column j."""
    eye = torch.eye(N_BASIS, dtype=torch.float64)
    A, b = affine_from_coefficients(eye)  # column j of Phi as the affine map x -> A(e_j) x + b(e_j)
    omega = eye[:, list(COLUMN_GROUPS["rotation"])]  # omega(e_j) = (w4, w5, w6) of e_j
    pure = torch.cat([torch.zeros(N_BASIS, 1, dtype=torch.float64), 0.5 * omega], dim=1)
    # Q_j[:, k] = 1/2 (0, omega(e_j)) (x) e_k: left multiplication as a matrix.
    Q = quat_multiply(pure[:, None, :], torch.eye(4, dtype=torch.float64)[None]).transpose(1, 2)
    G = torch.zeros(N_BASIS, 8, 8, dtype=torch.float64)
    G[:, 0:3, 0:3] = A
    G[:, 0:3, 3] = b
    G[:, 4:8, 4:8] = Q
    return G
