"""velogauss_fast.motion.velocity: VG-VEL (Phi(x) w) and VG-FIELD (v(x, t)) against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, RIGID_MASK, check_agreement, check_float32, gradcheck_fn,
                                     mlp_velocity_params, random_params, small_cfg, to_torch)
from velogauss_fast.motion.basis import basis_matrix
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import coefficients
from velogauss_fast.motion.velocity import mlp_velocity, velocity, velocity_field
from velogauss_ref.motion import velocity as ref

seeds = st.integers(0, 2**32 - 1)


@pytest.mark.spec("VG-VEL")
@DEVICE_SETTINGS
@given(seed=seeds, n=st.sampled_from([0, 1, 9]))
def test_velocity_reference_vs_fast(device, seed, n):
    rng = np.random.default_rng(seed)
    args = (rng.uniform(-3, 3, (n, 3)), rng.standard_normal((n, 12)))
    check_agreement(ref.velocity, velocity, args, diff=(0, 1), device=device, seed=seed)
    check_float32(ref.velocity, velocity, args, device)


@pytest.mark.spec("VG-VEL", "VG-BASIS")
def test_velocity_is_basis_times_coefficients(device):
    rng = np.random.default_rng(0)
    x = torch.tensor(rng.standard_normal((8, 3)), device=device)
    w = torch.tensor(rng.standard_normal((8, 12)), device=device)
    torch.testing.assert_close(velocity(x, w), (basis_matrix(x) @ w[..., None])[..., 0], rtol=0, atol=1e-13)


@pytest.mark.spec("VG-FIELD")
@DEVICE_SETTINGS
@given(seed=seeds, t=st.sampled_from([0.0, 0.6, -3.0, 12.0]), masked=st.booleans(), n=st.sampled_from([0, 5]))
def test_field_reference_vs_fast(device, seed, t, masked, n):
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (random_params(seed, cfg), x, t, cfg)
    check_agreement(ref.velocity_field, velocity_field, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.velocity_field, velocity_field, args, device)


@pytest.mark.spec("VG-FIELD", "VG-TRAJ")
def test_field_uses_the_code_at_the_query_point(device):
    cfg = small_cfg()
    params = to_torch(random_params(3, cfg), torch.float64, device)
    x = torch.tensor(np.random.default_rng(3).uniform(-1, 1, (6, 3)), device=device)
    w = coefficients(params, 0.3, physics_code(params, x, cfg), cfg)
    torch.testing.assert_close(velocity_field(params, x, 0.3, cfg), velocity(x, w), rtol=0, atol=1e-14)


@pytest.mark.spec("VG-VEL", "VG-FIELD")
def test_gradcheck(device):
    rng = np.random.default_rng(0)
    gradcheck_fn(velocity, (rng.standard_normal((3, 3)), rng.standard_normal((3, 12))), diff=(0, 1), device=device)
    cfg = small_cfg()
    args = (random_params(0, cfg), rng.uniform(-1, 1, (3, 3)), 0.25, cfg)
    gradcheck_fn(velocity_field, args, diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-VEL", "VG-FIELD")
def test_rejects_bad_input():
    with pytest.raises(ValueError, match="^w"):
        velocity(torch.zeros(3, 3), torch.zeros(4, 12))
    with pytest.raises(ValueError, match="^x"):
        velocity(torch.zeros(3, 4), torch.zeros(3, 12))
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    with pytest.raises(ValueError, match="^t"):
        velocity_field(params, torch.zeros(2, 3, dtype=torch.float64), float("inf"), cfg)
    with pytest.raises(ValueError, match="^x"):
        velocity_field(params, torch.zeros(2, 4, dtype=torch.float64), 0.0, cfg)


@pytest.mark.spec("VG-VEL-MLP")
@DEVICE_SETTINGS
@given(seed=seeds, t=st.sampled_from([0.0, 0.6, -3.0]), n=st.sampled_from([0, 5]))
def test_mlp_velocity_reference_vs_fast(device, seed, t, n):
    cfg = small_cfg()
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (mlp_velocity_params(seed, cfg), x, t, cfg)
    check_agreement(ref.mlp_velocity, mlp_velocity, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.mlp_velocity, mlp_velocity, args, device)
