"""velogauss_fast.motion.code: VG-CODE (z = E(gamma(x0))) against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn,
                                     random_params, small_cfg, to_torch)
from velogauss_fast.motion.code import physics_code
from velogauss_ref.motion import code as ref


@pytest.mark.spec("VG-CODE")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([0, 1, 7]), n_freqs_x=st.integers(0, 4))
def test_reference_vs_fast(device, seed, n, n_freqs_x):
    cfg = small_cfg(n_freqs_x=n_freqs_x)
    params = random_params(seed, cfg)
    x0 = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (params, x0, cfg)
    check_agreement(ref.physics_code, physics_code, args, diff=(0, 1), device=device, seed=seed)
    check_float32(ref.physics_code, physics_code, args, device)


@pytest.mark.spec("VG-CODE")
def test_shape_and_gradcheck(device):
    cfg = small_cfg()
    params = random_params(0, cfg)
    x0 = np.random.default_rng(0).uniform(-1, 1, (4, 3))
    z = physics_code(to_torch(params, torch.float64, device), torch.tensor(x0, device=device), cfg)
    assert z.shape == (4, cfg.code_dim)
    gradcheck_fn(physics_code, (params, x0, cfg), diff=(0, 1), device=device)


@pytest.mark.spec("VG-CODE")
def test_rejects_bad_input():
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    with pytest.raises(ValueError, match="^x0"):
        physics_code(params, torch.zeros(3, 2, dtype=torch.float64), cfg)
    with pytest.raises(ValueError, match="^x0"):
        physics_code(params, torch.zeros(3, dtype=torch.float64), cfg)
