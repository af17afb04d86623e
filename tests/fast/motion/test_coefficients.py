"""velogauss_fast.motion.coefficients: VG-COEF (w = m(z) P(t), masked) against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import (DEVICE_SETTINGS, RIGID_MASK, check_agreement, check_float32, gradcheck_fn,
                                     random_params, small_cfg, to_torch)
from torch.func import jvp

from velogauss_fast.motion.coefficients import centred, coefficients, mixing_weights, mixing_weights_jet
from velogauss_fast.nn import mlp, positional_encoding
from velogauss_ref.motion import coefficients as ref

times = st.sampled_from([0.0, 0.37, 1.0, -2.5, 6.0])


@pytest.mark.spec("VG-COEF", "VG-COEF-RIGID", "VG-COEF-HARM", "VG-COEF-COAST")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), t=times, n_freqs_t=st.integers(0, 2), masked=st.booleans(),
       n=st.sampled_from([0, 1, 6]), pattern_form=st.sampled_from(["mlp", "rigid", "harmonic"]),
       knots=st.sampled_from([2, 3]), future=st.sampled_from(["integrate", "coast"]))
def test_reference_vs_fast(device, seed, t, n_freqs_t, masked, n, pattern_form, knots, future):
    # pattern_form "rigid" or "harmonic": VG-COEF-RIGID's or VG-COEF-HARM's patterns
    # (n_freqs_t does not enter them); future "coast" reads them at min(t, 0.6) (VG-COEF-COAST).
    cfg = small_cfg(n_freqs_t=n_freqs_t, mask=RIGID_MASK if masked else None, pattern_form=pattern_form,
                    max_time=0.6, rigid_knots=knots, future=future)
    params = random_params(seed, cfg)
    z = np.random.default_rng(seed).standard_normal((n, cfg.code_dim))
    args = (params, t, z, cfg)
    # t is differentiated too: dw/dt is what the transport residual needs.
    check_agreement(ref.coefficients, coefficients, args, diff=(0, 1, 2), device=device, seed=seed)
    check_float32(ref.coefficients, coefficients, args, device)


@pytest.mark.spec("VG-COEF")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), t=times)
def test_convex_combination_of_patterns_and_mask(device, seed, t):
    cfg = small_cfg(mask=RIGID_MASK)
    # Patterns about the world's origin: P(t) is then the time network's output (VG-COEF-CENTRE).
    params = to_torch({**random_params(seed, cfg), "centre": np.zeros((cfg.n_patterns, 3))}, torch.float64, device)
    z = torch.tensor(np.random.default_rng(seed).standard_normal((20, cfg.code_dim)) * 3, device=device)
    w = coefficients(params, t, z, cfg)
    unmasked = coefficients(params, t, z, small_cfg())
    assert float(w[:, 6:].abs().max()) == 0.0
    torch.testing.assert_close(w[:, :6], unmasked[:, :6], rtol=0, atol=0)
    # Softmax weights make w a convex combination of the K patterns: every column lies
    # within the patterns' range (P(t) evaluated here through the public VG-MLP/VG-ENC).
    t_vec = torch.full((1,), float(t), dtype=torch.float64, device=device)
    P = mlp(params["time"], positional_encoding(t_vec, cfg.n_freqs_t)).reshape(cfg.n_patterns, 12)
    slack = 1e-12 * (1 + P.abs().max())
    assert bool((unmasked >= P.min(0).values - slack).all() and (unmasked <= P.max(0).values + slack).all())
    # With z-independent mixing (A = 0) every particle gets the same coefficients.
    identical = {**params, "mix": [(torch.zeros_like(params["mix"][0][0]), params["mix"][0][1])]}
    same_z = coefficients(identical, t, z, small_cfg())
    torch.testing.assert_close(same_z, same_z[:1].expand_as(same_z), rtol=0, atol=1e-14)


@pytest.mark.spec("VG-COEF", "VG-COEF-HARM")
@pytest.mark.parametrize("pattern_form", ["mlp", "harmonic"])
def test_gradcheck(device, pattern_form):
    cfg = small_cfg(mask=RIGID_MASK, pattern_form=pattern_form)
    z = np.random.default_rng(0).standard_normal((3, cfg.code_dim))
    gradcheck_fn(coefficients, (random_params(0, cfg), 0.4, z, cfg), diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-COEF")
def test_rejects_bad_input():
    cfg = small_cfg()
    params = to_torch(random_params(0, cfg), torch.float64, "cpu")
    z = torch.zeros(3, cfg.code_dim, dtype=torch.float64)
    with pytest.raises(ValueError, match="^t"):
        coefficients(params, float("nan"), z, cfg)
    with pytest.raises(ValueError, match="^t"):
        coefficients(params, torch.zeros(2, dtype=torch.float64), z, cfg)
    with pytest.raises(ValueError, match="^z"):
        coefficients(params, 0.5, torch.zeros(3, cfg.code_dim + 1, dtype=torch.float64), cfg)


@pytest.mark.spec("VG-COEF")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.sampled_from([0, 1, 6]), tangents=st.integers(1, 3))
def test_mixing_weights_jet_vs_autodiff(device, seed, n, tangents):
    # The softmax's derivative written out, against torch's forward mode, float64 (both
    # round only in the last bits).
    cfg = small_cfg()
    params = to_torch(random_params(seed, cfg), torch.float64, device)
    rng = np.random.default_rng(seed)
    z = torch.tensor(rng.standard_normal((n, cfg.code_dim)) * 3, device=device)
    dz = torch.tensor(rng.standard_normal((tangents, n, cfg.code_dim)), device=device)
    m, dm = mixing_weights_jet(params, z, dz)
    assert torch.equal(m, mixing_weights(params, z))
    for k in range(tangents):
        _, expected = jvp(lambda u: mixing_weights(params, u), (z,), (dz[k],))
        torch.testing.assert_close(dm[k], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-COEF-CENTRE")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_centred_reference_vs_fast(device, seed):
    rng = np.random.default_rng(seed)
    args = (rng.standard_normal((5, 12)), rng.standard_normal((5, 3)))
    check_agreement(ref.centred, centred, args, diff=(0, 1), device=device, seed=seed)
    # A batch of times (S, K, 12), as the trajectories read them, is the same per time.
    P = torch.as_tensor(rng.standard_normal((3, 5, 12)), device=device)
    c = torch.as_tensor(args[1], device=device)
    batched = centred(P, c)
    for s in range(3):
        torch.testing.assert_close(batched[s], centred(P[s], c), rtol=0, atol=0)
