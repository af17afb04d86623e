"""velogauss_fast.motion.rates and .generators: the per-stage kernels of base_state against the
reference's spec functions, mask by mask (VG-VEL, VG-ROTSCALE, VG-QUAT)."""

import numpy as np
import pytest
import torch

from tests.fast.motion.cases import RTOL64, assert_close, column_mask
from velogauss_fast.motion.rates import axis_products, layout, rate_plan, rotmat, state_rates
from velogauss_ref.motion.rotscale import rotscale_rates as ref_rotscale_rates
from velogauss_ref.motion.velocity import velocity as ref_velocity
from velogauss_ref.quaternion import quat_to_rotmat as ref_quat_to_rotmat

# Every way a scene's profile can leave parts of the state still (VG-BASIS column groups):
# with and without q (rotation), with and without log s (stretch, shear), and both.
MASKS = {
    "translation": column_mask("translation"),
    "rotation": column_mask("rotation"),
    "rigid": column_mask("translation", "rotation"),
    "stretch": column_mask("stretch"),
    "shear": column_mask("shear"),
    "translation+stretch+shear": column_mask("translation", "stretch", "shear"),
    "rotation+shear": column_mask("rotation", "shear"),
    "all": None,
}


def _inputs(rng, n):
    x = rng.uniform(-1, 1, (n, 3))
    q = rng.standard_normal((n, 4)) * rng.uniform(0.3, 3.0, (n, 1))  # any norm
    log_s = np.log(rng.uniform(0.01, 0.2, (n, 3)))
    w = rng.standard_normal((n, 12))
    return x, q, log_s, w


@pytest.mark.spec("VG-VEL", "VG-ROTSCALE")
@pytest.mark.parametrize("name", MASKS)
def test_state_rates_match_reference_rates(device, name):
    mask = MASKS[name]
    lay = layout(mask)
    x, q, log_s, w = _inputs(np.random.default_rng(len(name)), 7)
    w_masked = w if mask is None else w * mask  # VG-COEF: unselected columns are exactly 0
    q_dot, log_s_dot = ref_rotscale_rates(q, w_masked)
    # The state holds x, then q only with rotation, then log s only with stretch or shear.
    parts, expected = [x], [ref_velocity(x, w_masked)]
    if lay.rotation:
        parts, expected = parts + [q], expected + [q_dot]
    if lay.strain:
        parts, expected = parts + [log_s], expected + [log_s_dot]

    def tensor(a):
        return torch.tensor(np.ascontiguousarray(a), dtype=torch.float64, device=device)

    y = tensor(np.concatenate(parts, axis=1).T)
    w_active = tensor(w[:, list(lay.columns)].T)
    plan = rate_plan(mask, torch.float64, device)
    # Without rotation the strain rate uses R(q0) built once; it must equal rebuilding it.
    RR = axis_products(rotmat(tensor(q.T))) if lay.strain and not lay.rotation else None
    assert_close(state_rates(plan, w_active, y, RR).T, np.concatenate(expected, axis=1), RTOL64, name)


@pytest.mark.spec("VG-ROTSCALE")
def test_parts_left_out_have_zero_reference_rate():
    # What base_state leaves out of the integration really has rate 0 in the reference:
    # q without a rotation column, log s without a stretch or shear column (exactly 0.0).
    x, q, _, w = _inputs(np.random.default_rng(3), 5)
    for name, mask in MASKS.items():
        lay = layout(mask)
        q_dot, log_s_dot = ref_rotscale_rates(q, w if mask is None else w * mask)
        if not lay.rotation:
            assert not np.any(q_dot), name
        if not lay.strain:
            assert not np.any(log_s_dot), name


def test_layout_groups_columns():
    lay = layout(column_mask("translation", "stretch", "shear"))
    assert lay.columns == (0, 1, 2, 6, 7, 8, 9, 10, 11) and lay.sizes == (3, 0, 6)
    assert not lay.rotation and lay.strain and lay.width == 3
    lay = layout(None)
    assert lay.columns == tuple(range(12)) and lay.sizes == (3, 3, 6) and lay.width == 7
    assert layout(np.zeros(12, dtype=bool)).columns == ()


@pytest.mark.spec("VG-QUAT")
def test_rotmat_matches_reference(device):
    rng = np.random.default_rng(4)
    q = rng.standard_normal((9, 4)) * rng.uniform(0.1, 10.0, (9, 1))
    q[0] = 0.0  # zero quaternion: the identity
    q[1] = [1e-13, 0.0, 0.0, 0.0]  # |q|^2 = 1e-26 < QUAT_ZERO_NORM_SQ: the identity too
    q[2] = [0.0, 0.0, 0.0, -2.5]  # q and -q, any norm
    R = rotmat(torch.tensor(q.T.copy(), device=device))
    assert_close(R.T.reshape(9, 3, 3), ref_quat_to_rotmat(q), RTOL64)
    assert torch.equal(R[:, :2].T, torch.eye(3, dtype=R.dtype, device=device).reshape(1, 9).expand(2, 9))


@pytest.mark.spec("VG-QUAT")
def test_rotmat_zero_quaternion_has_zero_gradient(device):
    q = torch.zeros(4, 2, dtype=torch.float64, device=device, requires_grad=True)
    cotangent = torch.arange(1.0, 19.0, dtype=torch.float64, device=device).reshape(9, 2)
    (g,) = torch.autograd.grad((rotmat(q) * cotangent).sum(), q)
    assert torch.equal(g, torch.zeros_like(g))
