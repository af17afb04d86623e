"""velogauss_fast.motion.deform: VG-ADF (residual deformation field) and VG-ADF-COMPOSE
against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn, random_params,
                                     small_cfg, to_torch)
from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.quaternion import quat_to_rotmat
from velogauss_ref.motion import deform as ref

seeds = st.integers(0, 2**32 - 1)


@pytest.mark.spec("VG-ADF")
@DEVICE_SETTINGS
@given(seed=seeds, t=st.sampled_from([0.0, 0.8, -4.0, 15.0]), n=st.sampled_from([0, 1, 6]),
       n_freqs_adf_t=st.integers(0, 3))
def test_adf_reference_vs_fast(device, seed, t, n, n_freqs_adf_t):
    cfg = small_cfg(n_freqs_adf_t=n_freqs_adf_t)
    rng = np.random.default_rng(seed)
    args = (random_params(seed, cfg), rng.uniform(-1, 1, (n, 3)), t, rng.standard_normal((n, cfg.code_dim)), cfg)
    check_agreement(ref.adf_residual, adf_residual, args, diff=(0, 1, 2, 3), device=device, seed=seed)
    check_float32(ref.adf_residual, adf_residual, args, device)


@pytest.mark.spec("VG-ADF", "VG-ADF-COMPOSE")
def test_zero_last_layer_is_the_identity(device):
    cfg = small_cfg()
    params = random_params(0, cfg)
    W, b = params["adf"][-1]
    params["adf"][-1] = (np.zeros_like(W), np.zeros_like(b))
    params = to_torch(params, torch.float64, device)
    rng = np.random.default_rng(0)
    x0 = torch.tensor(rng.uniform(-1, 1, (4, 3)), device=device)
    z = torch.tensor(rng.standard_normal((4, cfg.code_dim)), device=device)
    dx, dq, ds = adf_residual(params, x0, 0.3, z, cfg)
    assert float(dx.abs().max()) == 0 and float(ds.abs().max()) == 0
    assert torch.equal(dq, torch.tensor([[1.0, 0, 0, 0]] * 4, dtype=torch.float64, device=device))
    q_star = torch.tensor(rng.standard_normal((4, 4)), device=device)
    s_star = torch.tensor(rng.uniform(0.1, 1, (4, 3)), device=device)
    x, q, s = compose_state(x0, q_star, s_star, dx, dq, ds)
    assert torch.equal(x, x0) and torch.equal(s, s_star)
    torch.testing.assert_close(q, q_star / q_star.norm(dim=-1, keepdim=True), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-ADF-COMPOSE")
@DEVICE_SETTINGS
@given(seed=seeds, n=st.sampled_from([0, 1, 7]))
def test_compose_reference_vs_fast(device, seed, n):
    rng = np.random.default_rng(seed)
    args = (rng.standard_normal((n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.01, 2, (n, 3)),
            0.1 * rng.standard_normal((n, 3)), np.array([1.0, 0, 0, 0]) + 0.3 * rng.standard_normal((n, 4)),
            0.2 * rng.standard_normal((n, 3)))
    check_agreement(ref.compose_state, compose_state, args, diff=(0, 1, 2, 3, 4, 5), device=device, seed=seed)
    check_float32(ref.compose_state, compose_state, args, device)


@pytest.mark.spec("VG-ADF-COMPOSE", "VG-QUAT-MUL")
def test_compose_rotates_by_the_correction_after_the_base(device):
    c = np.sqrt(0.5)
    q_star = torch.tensor([[c, 0, 0, c]], dtype=torch.float64, device=device)  # 90 degrees about z
    dq = torch.tensor([[2 * c, 2 * c, 0, 0]], dtype=torch.float64, device=device)  # 90 degrees about x, |dq| = 2
    zeros = torch.zeros(1, 3, dtype=torch.float64, device=device)
    _, q, _ = compose_state(zeros, q_star, torch.ones_like(zeros), zeros, dq, zeros)
    # R(q* (x) dq) = R(q*) R(dq): the correction acts in the base state's frame.
    expected = quat_to_rotmat(q_star) @ quat_to_rotmat(dq)
    torch.testing.assert_close(quat_to_rotmat(q), expected, rtol=0, atol=1e-15)
    torch.testing.assert_close(q.norm(dim=-1), torch.ones(1, dtype=torch.float64, device=device), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-ADF", "VG-ADF-COMPOSE")
def test_gradcheck(device):
    cfg = small_cfg()
    rng = np.random.default_rng(0)
    args = (random_params(0, cfg), rng.uniform(-1, 1, (3, 3)), 0.6, rng.standard_normal((3, cfg.code_dim)), cfg)
    gradcheck_fn(adf_residual, args, diff=(0, 1, 2, 3), device=device)
    args = (rng.standard_normal((3, 3)), rng.standard_normal((3, 4)), rng.uniform(0.1, 1, (3, 3)),
            rng.standard_normal((3, 3)), rng.standard_normal((3, 4)), rng.standard_normal((3, 3)))
    gradcheck_fn(compose_state, args, diff=(0, 1, 2, 3, 4, 5), device=device)


@pytest.mark.spec("VG-ADF", "VG-ADF-COMPOSE")
def test_rejects_bad_input():
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    x0 = torch.zeros(3, 3, dtype=torch.float64)
    z = torch.zeros(3, cfg.code_dim, dtype=torch.float64)
    with pytest.raises(ValueError, match="^z"):
        adf_residual(params, x0, 0.1, z[:2], cfg)
    with pytest.raises(ValueError, match="^t"):
        adf_residual(params, x0, float("nan"), z, cfg)
    with pytest.raises(ValueError, match="^x0"):
        adf_residual(params, x0[:, :2], 0.1, z, cfg)
    q = torch.ones(3, 4)
    with pytest.raises(ValueError, match="^dq"):
        compose_state(x0.float(), q, torch.ones(3, 3), torch.zeros(3, 3), torch.ones(2, 4), torch.zeros(3, 3))
    with pytest.raises(ValueError, match="^ds"):
        compose_state(x0.float(), q, torch.ones(3, 3), torch.zeros(3, 3), q, torch.zeros(3, 4))
