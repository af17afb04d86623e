"""velogauss_fast.motion.trajectory: VG-TRAJ (base state by integration) against
velogauss_ref and closed-form motions."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, RIGID_MASK, check_agreement, check_float32, column_mask,
                                     constant_coefficient_params, gradcheck_fn, random_params, small_cfg, to_torch)
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.quaternion import normalize_quat
from velogauss_fast.quaternion import quat_multiply, quat_to_rotmat
from velogauss_ref.motion import trajectory as ref


def _state(rng, n, cfg):
    return (rng.uniform(-1, 1, (n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.01, 0.2, (n, 3)),
            rng.standard_normal((n, cfg.code_dim)))


@pytest.mark.spec("VG-TRAJ")
@settings(DEVICE_SETTINGS, max_examples=15)
@given(seed=st.integers(0, 2**32 - 1), method=st.sampled_from(["euler", "rk2", "rk4"]),
       t=st.sampled_from([0.0, 0.45, -0.6, 1.0]), masked=st.booleans(), n=st.sampled_from([0, 4]))
def test_reference_vs_fast(device, seed, method, t, masked, n):
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    rng = np.random.default_rng(seed)
    args = (random_params(seed, cfg), *_state(rng, n, cfg), t, 0.125, method, cfg)
    # Gradients w.r.t. the parameters, every per-particle input and the end time t. The
    # cotangent's stream must not be the state's: from the same seed the q cotangent equals
    # q0 draw for draw, which normalisation's gradient annihilates, leaving rounding noise.
    check_agreement(ref.base_state, base_state, args, diff=(0, 1, 2, 3, 4, 5), device=device, seed=seed + 1)
    check_float32(ref.base_state, base_state, args, device)


# Masks that leave q, log s, or both out of the integration (velogauss_fast.motion.rates),
# and the empty mask, where nothing moves.
PARTIAL_MASKS = {
    "translation": column_mask("translation"),
    "rotation": column_mask("rotation"),
    "stretch": column_mask("stretch"),
    "shear": column_mask("shear"),
    "translation+stretch+shear": column_mask("translation", "stretch", "shear"),
    "rotation+stretch": column_mask("rotation", "stretch"),
    "none": np.zeros(12, dtype=bool),
}


@pytest.mark.spec("VG-TRAJ")
@pytest.mark.parametrize("method, t", [("euler", 0.45), ("rk2", -0.6), ("rk4", 1.0)])
@pytest.mark.parametrize("name", PARTIAL_MASKS)
def test_reference_vs_fast_per_mask(device, name, method, t):
    cfg = small_cfg(mask=PARTIAL_MASKS[name])
    seed = len(name)
    args = (random_params(seed, cfg), *_state(np.random.default_rng(seed), 4, cfg), t, 0.125, method, cfg)
    # Outputs and gradients w.r.t. the parameters, x0, q0, s0, z and t, as in
    # test_reference_vs_fast (RTOL64 of cases.py).
    check_agreement(ref.base_state, base_state, args, diff=(0, 1, 2, 3, 4, 5), device=device, seed=seed + 1)


@pytest.mark.spec("VG-TRAJ")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("name", PARTIAL_MASKS)
def test_still_parts_are_exactly_canonical(device, dtype, name):
    # q* is q0 normalised without a rotation column and s* is s0 without a stretch or shear
    # column, bit for bit: what integrating a rate of exactly 0 gives (exp(log s0) would not).
    mask = PARTIAL_MASKS[name]
    cfg = small_cfg(mask=mask)
    params = to_torch(random_params(5, cfg), dtype, device)
    x0, q0, s0, z = (torch.tensor(a, dtype=dtype, device=device) for a in _state(np.random.default_rng(5), 6, cfg))
    x, q, s = base_state(params, x0, q0, s0, z, 0.7, 0.05, "rk2", cfg)
    # Where a part does move, the same comparison must fail (it is not vacuous).
    for moves, out, canonical in ((mask[3:6].any(), q, normalize_quat(q0)), (mask[6:12].any(), s, s0),
                                  (mask.any(), x, x0)):
        assert torch.equal(out, canonical) == (not moves)


@pytest.mark.spec("VG-TRAJ")
def test_t_zero_returns_the_canonical_state(device):
    cfg = small_cfg()
    rng = np.random.default_rng(1)
    params = to_torch(random_params(1, cfg), torch.float64, device)
    x0, q0, s0, z = (torch.tensor(a, device=device) for a in _state(rng, 5, cfg))
    x, q, s = base_state(params, x0, q0, s0, z, 0.0, 0.1, "rk4", cfg)
    assert torch.equal(x, x0)
    torch.testing.assert_close(s, s0, rtol=1e-15, atol=0)  # exp(log s0): one rounding each
    torch.testing.assert_close(q, q0 / q0.norm(dim=-1, keepdim=True), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
def test_constant_spin_is_a_rigid_rotation(device):
    # w = spin omega about the origin: x(t) = Rz(omega t) x0, q(t) = rot(omega t) (x) q0, s = s0.
    omega = np.array([0.0, 0.0, 1.3])
    w = np.zeros(12)
    w[3:6] = omega
    cfg = small_cfg()
    params = to_torch(constant_coefficient_params(2, cfg, w), torch.float64, device)
    rng = np.random.default_rng(2)
    x0, q0, s0, z = (torch.tensor(a, device=device) for a in _state(rng, 6, cfg))
    t = 0.9
    x, q, s = base_state(params, x0, q0, s0, z, t, 0.01, "rk4", cfg)
    a = omega[2] * t
    Rz = torch.tensor([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]],
                      dtype=torch.float64, device=device)
    # RK4 at h = 0.01: global error ~ (h omega)^4 ~ 3e-8 relative to O(1) values.
    torch.testing.assert_close(x, x0 @ Rz.T, rtol=0, atol=1e-7)
    torch.testing.assert_close(s, s0, rtol=1e-7, atol=0)
    rot = torch.tensor([math.cos(a / 2), 0, 0, math.sin(a / 2)], dtype=torch.float64, device=device)
    expected_q = quat_multiply(rot, q0 / q0.norm(dim=-1, keepdim=True))
    torch.testing.assert_close(quat_to_rotmat(q), quat_to_rotmat(expected_q), rtol=0, atol=1e-7)


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
@pytest.mark.parametrize("method", ["euler", "rk2", "rk4"])
def test_translation_and_axis_stretch_are_exact(device, method):
    # Constant translation b gives x = x0 + b t, and stretch rates k with identity
    # orientation give s = s0 exp(k t) exactly for every method: log s has a constant rate.
    # (Stretch also moves x: exact solution x_i = (x0_i + b_i / k_i) e^{k_i t} - b_i / k_i.)
    w = np.zeros(12)
    w[0:3] = [0.5, -1.0, 0.25]
    w[6:9] = [0.4, -0.3, 0.0]
    cfg = small_cfg()
    params = to_torch(constant_coefficient_params(4, cfg, w), torch.float64, device)
    rng = np.random.default_rng(4)
    x0, _, s0, z = (torch.tensor(a, device=device) for a in _state(rng, 5, cfg))
    q0 = torch.tensor([[1.0, 0, 0, 0]] * 5, dtype=torch.float64, device=device)
    t = -0.8
    x, q, s = base_state(params, x0, q0, s0, z, t, 0.001, method, cfg)
    k = torch.tensor(w[6:9], dtype=torch.float64, device=device)
    b = torch.tensor(w[0:3], dtype=torch.float64, device=device)
    torch.testing.assert_close(s, s0 * torch.exp(k * t), rtol=1e-12, atol=0)
    torch.testing.assert_close(q, q0, rtol=0, atol=1e-15)
    safe_k = torch.where(k == 0, torch.ones_like(k), k)
    exact = torch.where(k == 0, x0 + b * t, (x0 + b / safe_k) * torch.exp(k * t) - b / safe_k)
    # Euler's global error at h = 1e-3 is ~ h k^2 t |x| / 2 ~ 1e-4; RK2/RK4 are far below.
    tol = {"euler": 3e-4, "rk2": 1e-7, "rk4": 1e-12}[method]
    torch.testing.assert_close(x, exact, rtol=0, atol=tol)


@pytest.mark.spec("VG-TRAJ")
def test_gradcheck(device):
    cfg = small_cfg(mask=RIGID_MASK)
    rng = np.random.default_rng(0)
    # t / h = 2.2: finite differences in t must not cross a change of the step count
    # ceil(|t| / h), where base_state jumps.
    args = (random_params(0, cfg), *_state(rng, 2, cfg), 0.55, 0.25, "rk2", cfg)
    gradcheck_fn(base_state, args, diff=(0, 1, 2, 3, 4, 5), device=device)


@pytest.mark.spec("VG-TRAJ")
def test_rejects_bad_input():
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    x0, q0, s0, z = (torch.tensor(a) for a in _state(np.random.default_rng(0), 3, cfg))
    with pytest.raises(ValueError, match="^s0"):
        base_state(params, x0, q0, s0[:, :2], z, 0.5, 0.1, "rk2", cfg)
    with pytest.raises(ValueError, match="^q0"):
        base_state(params, x0, q0[:2], s0, z, 0.5, 0.1, "rk2", cfg)
    with pytest.raises(ValueError, match="^z"):
        base_state(params, x0, q0, s0, z[:, :2], 0.5, 0.1, "rk2", cfg)
    with pytest.raises(ValueError, match="^h"):
        base_state(params, x0, q0, s0, z, 0.5, 0.0, "rk2", cfg)
    with pytest.raises(ValueError, match="^t"):
        base_state(params, x0, q0, s0, z, float("nan"), 0.1, "rk2", cfg)
    with pytest.raises(ValueError, match="^method"):
        base_state(params, x0, q0, s0, z, 0.5, 0.1, "midpoint", cfg)
