"""velogauss_fast.physics.residuals: VG-TRANSPORT and VG-DIV (batched forward-mode) against
the reference's per-point reverse-mode autograd, and closed forms."""

import dataclasses

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, RIGID_MASK, check_agreement, check_float32,
                                     constant_coefficient_params, gradcheck_fn, mlp_velocity_params, random_params, small_cfg,
                                     to_torch)
from velogauss_fast.physics.residuals import divergence, mlp_residuals, physics_residuals, transport_residual
from velogauss_ref.physics import residuals as ref


def ref_both(params, x, t, cfg):
    return ref.transport_residual(params, x, t, cfg), ref.divergence(params, x, t, cfg)


cases = dict(seed=st.integers(0, 2**32 - 1), t=st.sampled_from([0.0, 0.4, -1.5, 7.0]), masked=st.booleans(),
             n=st.sampled_from([0, 1, 3]), n_freqs_t=st.integers(0, 2),
             pattern_form=st.sampled_from(["mlp", "rigid", "harmonic"]))


def _args(seed, t, masked, n, n_freqs_t, pattern_form):
    # pattern_form "rigid" or "harmonic" (VG-COEF-RIGID, VG-COEF-HARM with VG-ACC-HARM): the
    # fast path's closed-form dP/dt against the reference's autograd.
    cfg = small_cfg(mask=RIGID_MASK if masked else None, n_freqs_t=n_freqs_t, pattern_form=pattern_form,
                    max_time=0.6, rigid_knots=2 + seed % 2,
                    acc_form="harmonic" if pattern_form == "harmonic" else "poly")
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    return (random_params(seed, cfg), x, t, cfg)


# The reference differentiates per point (and twice for the gradients): a few examples suffice.
@pytest.mark.spec("VG-TRANSPORT")
@settings(DEVICE_SETTINGS, max_examples=10)
@given(**cases)
def test_transport_reference_vs_fast(device, seed, t, masked, n, n_freqs_t, pattern_form):
    args = _args(seed, t, masked, n, n_freqs_t, pattern_form)
    # Gradients w.r.t. params, x and t: the physics loss backpropagates through the JVPs.
    check_agreement(ref.transport_residual, transport_residual, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.transport_residual, transport_residual, args, device)


@pytest.mark.spec("VG-DIV")
@settings(DEVICE_SETTINGS, max_examples=10)
@given(**cases)
def test_divergence_reference_vs_fast(device, seed, t, masked, n, n_freqs_t, pattern_form):
    args = _args(seed, t, masked, n, n_freqs_t, pattern_form)
    check_agreement(ref.divergence, divergence, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.divergence, divergence, args, device)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
@settings(DEVICE_SETTINGS, max_examples=6)
@given(**cases)
def test_shared_jet_reference_vs_fast(device, seed, t, masked, n, n_freqs_t, pattern_form):
    args = _args(seed, t, masked, n, n_freqs_t, pattern_form)
    check_agreement(ref_both, physics_residuals, args, diff=(0, 1, 2), device=device, seed=seed)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV", "VG-COEF-COAST")
@pytest.mark.parametrize("pattern_form", ["mlp", "rigid", "harmonic"])
def test_coasting_leaves_the_residuals_past_the_window_to_the_forms_own_patterns(device, pattern_form):
    # A training loss: under future "coast" both twins read each form's own patterns at t = 7,
    # past the window's end 0.6, as under "integrate" (the fast path's closed-form rates).
    params, x, t, cfg = _args(1, 7.0, False, 3, 1, pattern_form)
    coast = dataclasses.replace(cfg, future="coast")
    check_agreement(ref_both, physics_residuals, (params, x, t, coast), diff=(0, 1, 2), device=device, seed=1)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
def test_constant_coefficients_closed_form(device):
    # Constant w: grad v = A(w), dv/dt = 0, so r = A (A x + b) - a and div = w7 + w8 + w9.
    rng = np.random.default_rng(5)
    w = rng.standard_normal(12)
    acc = rng.standard_normal((3, 12))
    cfg = small_cfg()
    params = to_torch(constant_coefficient_params(5, cfg, w, acc=acc), torch.float64, device)
    x = torch.tensor(rng.uniform(-1, 1, (7, 3)), device=device)
    t = 0.3
    A = torch.tensor([[w[6], w[9] - w[5], w[4] + w[11]],
                      [w[9] + w[5], w[7], w[10] - w[3]],
                      [w[11] - w[4], w[10] + w[3], w[8]]], dtype=torch.float64, device=device)
    b = torch.tensor(w[:3], device=device)
    alpha = torch.tensor(acc[0] + acc[1] * t + acc[2] * t * t, device=device)
    Aa = torch.tensor([[alpha[6], alpha[9] - alpha[5], alpha[4] + alpha[11]],
                       [alpha[9] + alpha[5], alpha[7], alpha[10] - alpha[3]],
                       [alpha[11] - alpha[4], alpha[10] + alpha[3], alpha[8]]], dtype=torch.float64, device=device)
    v = x @ A.T + b
    expected_r = v @ A.T - (x @ Aa.T + alpha[:3])
    torch.testing.assert_close(transport_residual(params, x, t, cfg), expected_r, rtol=0, atol=1e-12)
    div = divergence(params, x, t, cfg)
    torch.testing.assert_close(div, torch.full_like(div, w[6] + w[7] + w[8]), rtol=0, atol=1e-12)


@pytest.mark.spec("VG-TRANSPORT", "VG-ACC")
def test_spin_of_a_rigid_scene_needs_the_wider_acc_mask(device):
    # v = omega x x under the rigid velocity mask; its material acceleration Omega^2 x is
    # symmetric (stretch and shear columns), which only acc_mask (here None: all 12
    # columns) lets a represent. Masking a by the velocity's mask would leave r = Omega^2 x.
    omega = np.array([0.3, -0.8, 0.5])
    w = np.zeros(12)
    w[3:6] = omega
    M = np.outer(omega, omega) - omega @ omega * np.eye(3)  # Omega^2
    alpha = np.zeros(12)
    alpha[6:9] = np.diag(M)
    alpha[9:12] = [M[0, 1], M[1, 2], M[0, 2]]
    acc = np.zeros((3, 12))
    acc[0] = alpha
    cfg = small_cfg(mask=RIGID_MASK)
    params = to_torch(constant_coefficient_params(3, cfg, w, acc=acc), torch.float64, device)
    x = torch.tensor(np.random.default_rng(3).uniform(-1, 1, (5, 3)), device=device)
    # Roundings of O(1) values through a few products.
    torch.testing.assert_close(transport_residual(params, x, 0.2, cfg), torch.zeros_like(x), rtol=0, atol=1e-13)
    narrow = small_cfg(mask=RIGID_MASK, acc_mask=RIGID_MASK)
    expected = x @ torch.tensor(M.T, device=device)
    torch.testing.assert_close(transport_residual(params, x, 0.2, narrow), expected, rtol=0, atol=1e-13)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
def test_tensor_time_is_differentiable(device):
    # d r / d t through a 0-d tensor time, against central differences of the residual.
    cfg = small_cfg(n_freqs_t=1)
    params = to_torch(random_params(7, cfg), torch.float64, device)
    x = torch.tensor(np.random.default_rng(7).uniform(-1, 1, (4, 3)), device=device)
    t = torch.tensor(0.35, dtype=torch.float64, device=device, requires_grad=True)
    (g,) = torch.autograd.grad(transport_residual(params, x, t, cfg).sum(), t)
    h = 1e-5
    fd = (transport_residual(params, x, 0.35 + h, cfg).sum() - transport_residual(params, x, 0.35 - h, cfg).sum()) / (2 * h)
    # Central difference: truncation ~ h^2 |r'''| ~ 1e-10, rounding ~ 1e-16 |r| / h ~ 1e-11.
    assert abs(float(g) - float(fd)) < 1e-7 * max(1.0, abs(float(fd)))


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
def test_gradcheck(device):
    cfg = small_cfg()
    x = np.random.default_rng(0).uniform(-1, 1, (3, 3))
    args = (random_params(0, cfg), x, 0.45, cfg)
    gradcheck_fn(transport_residual, args, diff=(0, 1, 2), device=device)
    gradcheck_fn(divergence, args, diff=(0, 1, 2), device=device)
    gradcheck_fn(physics_residuals, args, diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
@pytest.mark.parametrize("fn", [transport_residual, divergence, physics_residuals])
def test_rejects_bad_input(fn):
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    with pytest.raises(ValueError, match="^x"):
        fn(params, torch.zeros(2, 4, dtype=torch.float64), 0.1, cfg)
    with pytest.raises(ValueError, match="^x"):
        fn(params, torch.zeros(2, 3, dtype=torch.int64), 0.1, cfg)
    with pytest.raises(ValueError, match="^t"):
        fn(params, torch.zeros(2, 3, dtype=torch.float64), float("nan"), cfg)


def _mlp_both(params, x, t, cfg):
    return mlp_residuals(params, x, t, cfg, with_divergence=True)


def _ref_mlp_both(params, x, t, cfg):
    return ref.mlp_residuals(params, x, t, cfg, with_divergence=True)


@pytest.mark.spec("VG-TRANSPORT-MLP")
@settings(DEVICE_SETTINGS, max_examples=6)
@given(seed=st.integers(0, 2**32 - 1), t=st.sampled_from([0.0, 0.4, -1.5]), n=st.sampled_from([0, 1, 3]))
def test_mlp_residuals_reference_vs_fast(device, seed, t, n):
    cfg = small_cfg()
    x = np.random.default_rng(seed).uniform(-1.5, 1.5, (n, 3))
    args = (mlp_velocity_params(seed, cfg), x, t, cfg)
    check_agreement(_ref_mlp_both, _mlp_both, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(_ref_mlp_both, _mlp_both, args, device)
