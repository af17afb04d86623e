"""velogauss_fast.physics.acceleration: VG-ACC against velogauss_ref and closed forms."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, RIGID_MASK, TRANSLATION_MASK, check_agreement, check_float32,
                                     constant_coefficient_params, gradcheck_fn, random_params, small_cfg, to_torch)
from velogauss_fast.physics.acceleration import acceleration_field, harmonic_patterns, rigid_patterns
from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_ref.physics import acceleration as ref


@pytest.mark.spec("VG-ACC")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), t=st.sampled_from([0.0, 0.5, -2.0, 9.0]), masked=st.booleans(),
       acc_masked=st.booleans(), n=st.sampled_from([0, 1, 6]))
def test_reference_vs_fast(device, seed, t, masked, acc_masked, n):
    cfg = small_cfg(mask=RIGID_MASK if masked else None, acc_mask=TRANSLATION_MASK if acc_masked else None)
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (random_params(seed, cfg), x, t, cfg)
    check_agreement(ref.acceleration_field, acceleration_field, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.acceleration_field, acceleration_field, args, device)


@pytest.mark.spec("VG-ACC")
def test_polynomial_in_time(device):
    # Every pattern's alpha = g + c1 t + c2 t^2 (translation columns only): a(x, t) = alpha[:3].
    assert ACC_POLY_DEGREE == 2
    acc = np.zeros((3, 12))
    acc[0, :3] = [0.0, 0.0, -9.81]
    acc[1, :3] = [1.0, 0.0, 0.0]
    acc[2, :3] = [0.0, 0.5, 0.0]
    cfg = small_cfg()
    params = to_torch(constant_coefficient_params(0, cfg, np.zeros(12), acc=acc), torch.float64, device)
    x = torch.tensor(np.random.default_rng(0).uniform(-1, 1, (5, 3)), device=device)
    t = 2.0
    expected = torch.tensor([[t, 0.5 * t * t, -9.81]] * 5, dtype=torch.float64, device=device)
    torch.testing.assert_close(acceleration_field(params, x, t, cfg), expected, rtol=0, atol=1e-13)
    zero = {**params, "acc": torch.zeros_like(params["acc"])}
    assert float(acceleration_field(zero, x, t, cfg).abs().max()) == 0.0


@pytest.mark.spec("VG-ACC")
def test_acc_mask_not_mask_applies(device):
    # Every pattern's alpha is the same constant with all 12 columns set, so a = A(alpha) x +
    # alpha[:3] unmasked. The velocity's mask must leave a alone; the acceleration's own
    # mask must cut it to the translation columns.
    alpha = np.linspace(0.1, 1.2, 12)
    acc = np.zeros((3, 12))
    acc[0] = alpha
    x_np = np.random.default_rng(1).uniform(-1, 1, (5, 3))
    x = torch.tensor(x_np, device=device)
    A = np.array([[alpha[6], alpha[9] - alpha[5], alpha[4] + alpha[11]],
                  [alpha[9] + alpha[5], alpha[7], alpha[10] - alpha[3]],
                  [alpha[11] - alpha[4], alpha[10] + alpha[3], alpha[8]]])
    full = x_np @ A.T + alpha[:3]
    translation_only = np.broadcast_to(alpha[:3], (5, 3))

    def a(**masks):
        cfg = small_cfg(**masks)
        params = to_torch(constant_coefficient_params(1, cfg, np.zeros(12), acc=acc), torch.float64, device)
        return acceleration_field(params, x, 0.6, cfg).cpu().numpy()

    # A handful of roundings of O(1) values.
    np.testing.assert_allclose(a(mask=RIGID_MASK), full, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(mask=TRANSLATION_MASK), full, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(mask=RIGID_MASK, acc_mask=TRANSLATION_MASK), translation_only, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(acc_mask=TRANSLATION_MASK), translation_only, rtol=0, atol=1e-13)


@pytest.mark.spec("VG-ACC")
def test_gradcheck(device):
    cfg = small_cfg()
    x = np.random.default_rng(0).uniform(-1, 1, (3, 3))
    gradcheck_fn(acceleration_field, (random_params(0, cfg), x, 0.7, cfg), diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-ACC")
def test_rejects_bad_input():
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    with pytest.raises(ValueError, match="^x"):
        acceleration_field(params, torch.zeros(2, 2, dtype=torch.float64), 0.1, cfg)
    with pytest.raises(ValueError, match="^t"):
        acceleration_field(params, torch.zeros(2, 3, dtype=torch.float64), float("-inf"), cfg)


@pytest.mark.spec("VG-ACC-RIGID")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), t=st.sampled_from([0.0, 0.5, -2.0, 9.0]), n=st.sampled_from([0, 1, 6]))
def test_rigid_reference_vs_fast(device, seed, t, n):
    cfg = small_cfg(acc_form="rigid")
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (random_params(seed, cfg), x, t, cfg)
    check_agreement(ref.acceleration_field, acceleration_field, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.acceleration_field, acceleration_field, args, device)
    R = np.random.default_rng(seed).standard_normal((5, 12))
    check_agreement(ref.rigid_patterns, rigid_patterns, (R, t), diff=(0, 1), device=device, seed=seed)


@pytest.mark.spec("VG-ACC-HARM")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), t=st.sampled_from([0.0, 0.5, -2.0, 9.0]), n=st.sampled_from([0, 1, 6]))
def test_harmonic_reference_vs_fast(device, seed, t, n):
    cfg = small_cfg(pattern_form="harmonic", acc_form="harmonic")
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (random_params(seed, cfg), x, t, cfg)
    check_agreement(ref.acceleration_field, acceleration_field, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.acceleration_field, acceleration_field, args, device)
    rng = np.random.default_rng(seed)
    Q, omega = rng.standard_normal((5, 4, 12)), rng.uniform(1, 20, 1)
    check_agreement(ref.harmonic_patterns, harmonic_patterns, (Q, omega, t), diff=(0, 1, 2), device=device,
                    seed=seed)


@pytest.mark.spec("VG-ACC-HARM")
def test_harmonic_gradcheck(device):
    cfg = small_cfg(pattern_form="harmonic", acc_form="harmonic")
    x = np.random.default_rng(0).uniform(-1, 1, (3, 3))
    gradcheck_fn(acceleration_field, (random_params(0, cfg), x, 0.7, cfg), diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-ACC-RIGID")
def test_rigid_gradcheck(device):
    cfg = small_cfg(acc_form="rigid")
    x = np.random.default_rng(0).uniform(-1, 1, (3, 3))
    gradcheck_fn(acceleration_field, (random_params(0, cfg), x, 0.7, cfg), diff=(0, 1, 2), device=device)
