"""velogauss_fast.motion.carry and base_state's start time against velogauss_ref
(VG-STEP, VG-ADF-STATE, VG-CARRY), float64 outputs and gradients."""

import numpy as np
import pytest

from tests.fast.motion.cases import RIGID_MASK, check_agreement, random_params, small_cfg
from velogauss_fast.motion import carry as fast
from velogauss_fast.motion.trajectory import base_state
from velogauss_ref.motion import carry as ref
from velogauss_ref.motion import trajectory as ref_trajectory


def _state(rng, n, cfg):
    return (rng.uniform(-1, 1, (n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.05, 0.2, (n, 3)),
            rng.standard_normal((n, cfg.code_dim)))


def _step_ref(params, x, q, s, z, t0, t, h, method, cfg):
    return ref_trajectory.base_state(params, x, q, s, z, t, h, method, cfg, t0=t0)


def _step_fast(params, x, q, s, z, t0, t, h, method, cfg):
    return base_state(params, x, q, s, z, t, h, method, cfg, t0=t0)


@pytest.mark.spec("VG-STEP")
@pytest.mark.parametrize("method", ["euler", "rk2", "rk4"])
@pytest.mark.parametrize("masked", [False, True])
def test_step_reference_vs_fast(device, method, masked):
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    args = (random_params(1, cfg), *_state(np.random.default_rng(1), 4, cfg), 0.33, 0.9, 0.125, method, cfg)
    check_agreement(_step_ref, _step_fast, args, diff=(0, 1, 2, 3, 4, 5, 6), device=device, seed=2)


@pytest.mark.spec("VG-ADF-STATE")
def test_adf_state_reference_vs_fast(device):
    cfg = small_cfg()
    args = (random_params(3, cfg), *_state(np.random.default_rng(3), 4, cfg), 0.6, cfg)
    check_agreement(ref.adf_state, fast.adf_state, args, diff=(0, 1, 2, 3, 4, 5), device=device, seed=4)


@pytest.mark.spec("VG-CARRY")
@pytest.mark.parametrize("t, t_start", [(0.5, 0.45), (0.5, 0.55), (0.95, 0.75), (0.3, 0.3)])
@pytest.mark.parametrize("masked", [False, True])
def test_carried_state_reference_vs_fast(device, t, t_start, masked):
    # Outputs and gradients (with their stop-gradients) w.r.t. the parameters and every
    # per-particle input.
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    args = (random_params(5, cfg), *_state(np.random.default_rng(5), 4, cfg), t, t_start, 0.05, "rk2", cfg)
    check_agreement(ref.carried_state, fast.carried_state, args, diff=(0, 1, 2, 3, 4), device=device, seed=6)


@pytest.mark.spec("VG-LOSS-CARRY")
@pytest.mark.parametrize("t_a, t", [(0.1, 0.35), (0.6, 0.3), (0.4, 0.4)])
def test_carry_loss_reference_vs_fast(device, t_a, t):
    cfg = small_cfg(mask=RIGID_MASK)
    args = (random_params(7, cfg), *_state(np.random.default_rng(7), 4, cfg), t_a, t, 0.05, "rk2", cfg)
    check_agreement(ref.carry_loss, fast.carry_loss, args, diff=(0, 1, 2, 3, 4), device=device, seed=8)
