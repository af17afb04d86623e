"""velogauss_fast.nn: VG-ENC (positional encoding) and VG-MLP against velogauss_ref.nn."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import settings
from hypothesis import strategies as st

from tests.fast.motion.cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from torch.func import jacrev, jvp

from velogauss_fast.nn import mlp, mlp_jet, positional_encoding, positional_encoding_jet
from velogauss_ref import nn as ref

seeds = st.integers(0, 2**32 - 1)


def _layers(rng, dims):
    return [(rng.standard_normal((a, b)) / np.sqrt(a), rng.standard_normal(b)) for a, b in zip(dims[:-1], dims[1:])]


@pytest.mark.spec("VG-ENC")
def test_encoding_known_values(device):
    x = torch.tensor([[0.5, 0.25]], dtype=torch.float64, device=device)
    g = positional_encoding(x, 2)
    s = math.sqrt(0.5)
    # [x, sin(pi x), cos(pi x), sin(2 pi x), cos(2 pi x)], each block D = 2 wide.
    expected = [0.5, 0.25, 1.0, s, 0.0, s, 0.0, 1.0, -1.0, 0.0]
    np.testing.assert_allclose(g.cpu().numpy()[0], expected, atol=1e-15)
    assert torch.equal(positional_encoding(x, 0), x)


@pytest.mark.spec("VG-ENC")
@DEVICE_SETTINGS
@given(seed=seeds, n_freqs=st.integers(0, 5), shape=st.sampled_from([(4, 3), (2, 3, 1), (0, 3), (5,)]))
def test_encoding_reference_vs_fast(device, seed, n_freqs, shape):
    x = np.random.default_rng(seed).uniform(-2, 2, shape)
    check_agreement(ref.positional_encoding, positional_encoding, (x, n_freqs), diff=(0,), device=device, seed=seed)
    check_float32(ref.positional_encoding, positional_encoding, (x, n_freqs), device)


@pytest.mark.spec("VG-ENC")
def test_encoding_gradcheck(device):
    x = np.random.default_rng(0).uniform(-1, 1, (3, 2))
    gradcheck_fn(positional_encoding, (x, 3), diff=(0,), device=device)


@pytest.mark.spec("VG-ENC")
@pytest.mark.parametrize("n_freqs", [-1, 1.5, True, None])
def test_encoding_rejects_bad_n_freqs(n_freqs):
    with pytest.raises(ValueError, match="n_freqs"):
        positional_encoding(torch.zeros(2, 3), n_freqs)


@pytest.mark.spec("VG-ENC")
@pytest.mark.parametrize("x", [torch.tensor(0.5), torch.zeros(2, 3, dtype=torch.int64), np.zeros((2, 3))])
def test_encoding_rejects_bad_x(x):
    with pytest.raises(ValueError, match="^x"):
        positional_encoding(x, 2)


@pytest.mark.spec("VG-MLP")
def test_mlp_is_affine_then_silu(device):
    W0, b0 = torch.tensor([[1.0, -2.0]]), torch.tensor([0.5, 0.0])
    W1, b1 = torch.tensor([[3.0], [1.0]]), torch.tensor([-1.0])
    layers = [(t.double().to(device), u.double().to(device)) for t, u in ((W0, b0), (W1, b1))]
    x = torch.tensor([[0.7]], dtype=torch.float64, device=device)
    h = torch.tensor([0.7 + 0.5, -1.4], dtype=torch.float64)
    silu = h / (1 + torch.exp(-h))
    expected = 3 * silu[0] + silu[1] - 1
    assert abs(float(mlp(layers, x)[0, 0]) - float(expected)) < 1e-15


@pytest.mark.spec("VG-MLP")
@DEVICE_SETTINGS
@given(seed=seeds, depth=st.integers(1, 4), batch=st.sampled_from([(5,), (2, 3), (0,)]))
def test_mlp_reference_vs_fast(device, seed, depth, batch):
    rng = np.random.default_rng(seed)
    dims = [4] + [6] * (depth - 1) + [3]
    layers = _layers(rng, dims)
    x = rng.uniform(-2, 2, batch + (4,))
    # mlp takes a list of pairs, not a dict: wrap it so the helper converts the arrays.
    ref_fn = lambda p, xx: ref.mlp(p["layers"], xx)  # noqa: E731
    fast_fn = lambda p, xx: mlp(p["layers"], xx)  # noqa: E731
    check_agreement(ref_fn, fast_fn, ({"layers": layers}, x), diff=(0, 1), device=device, seed=seed)
    check_float32(ref_fn, fast_fn, ({"layers": layers}, x), device)


@pytest.mark.spec("VG-MLP")
def test_mlp_gradcheck(device):
    rng = np.random.default_rng(1)
    params = {"layers": _layers(rng, [3, 5, 5, 2])}
    gradcheck_fn(lambda p, x: mlp(p["layers"], x), (params, rng.standard_normal((4, 3))), diff=(0, 1), device=device)


@pytest.mark.spec("VG-MLP")
def test_mlp_rejects_bad_input():
    layers = [(torch.zeros(3, 4), torch.zeros(4)), (torch.zeros(4, 2), torch.zeros(2))]
    with pytest.raises(ValueError, match="^x"):
        mlp(layers, torch.zeros(5, 2))
    with pytest.raises(ValueError, match="^x"):
        mlp(layers, torch.zeros(5, 3, dtype=torch.int64))
    with pytest.raises(ValueError, match="layers"):
        mlp([], torch.zeros(5, 3))
    with pytest.raises(ValueError, match=r"layers\[1\]"):
        mlp([layers[0], (torch.zeros(5, 2), torch.zeros(2))], torch.zeros(5, 3))


# The jets: forward-mode derivatives written out by hand (the physics residuals' grad v and
# dv/dt), against torch's own autodiff of `positional_encoding` and `mlp` in float64. Both
# sides round differently only in the last bits: 1e-12 relative holds with a wide margin.
@pytest.mark.spec("VG-ENC")
@settings(DEVICE_SETTINGS, max_examples=20)
@given(seed=seeds, n_freqs=st.integers(0, 4), shape=st.sampled_from([(4, 3), (2, 3, 2), (0, 3), (1, 1)]))
def test_encoding_jet_vs_autodiff(device, seed, n_freqs, shape):
    x = torch.tensor(np.random.default_rng(seed).uniform(-2, 2, shape), device=device)
    gamma, J = positional_encoding_jet(x, n_freqs)
    assert torch.equal(gamma, positional_encoding(x, n_freqs))
    D = shape[-1]
    assert J.shape == (D,) + gamma.shape
    for j in range(D):
        e = torch.zeros_like(x)
        e[..., j] = 1
        _, expected = jvp(lambda y: positional_encoding(y, n_freqs), (x,), (e,))
        torch.testing.assert_close(J[j], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-MLP")
@settings(DEVICE_SETTINGS, max_examples=20)
@given(seed=seeds, depth=st.integers(1, 4), batch=st.sampled_from([(5,), (2, 3), (0,)]), tangents=st.integers(1, 3))
def test_mlp_jet_vs_autodiff(device, seed, depth, batch, tangents):
    rng = np.random.default_rng(seed)
    layers = [(torch.tensor(W, device=device), torch.tensor(b, device=device))
              for W, b in _layers(rng, [4] + [6] * (depth - 1) + [3])]
    x = torch.tensor(rng.uniform(-2, 2, batch + (4,)), device=device)
    dx = torch.tensor(rng.standard_normal((tangents,) + batch + (4,)), device=device)
    y, dy = mlp_jet(layers, x, dx)
    assert torch.equal(y, mlp(layers, x))  # the same operations as mlp
    for k in range(tangents):
        _, expected = jvp(lambda u: mlp(layers, u), (x,), (dx[k],))
        torch.testing.assert_close(dy[k], expected, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-MLP")
def test_mlp_jet_gradients_vs_autodiff(device):
    # Reverse mode through the hand-written jet equals reverse over torch's forward mode:
    # what the physics loss backpropagates through.
    rng = np.random.default_rng(3)
    layers = [(torch.tensor(W, device=device), torch.tensor(b, device=device)) for W, b in _layers(rng, [3, 5, 5, 2])]
    x = torch.tensor(rng.uniform(-1, 1, (4, 3)), device=device)
    dx = torch.tensor(rng.standard_normal((3, 4, 3)), device=device)
    v = torch.tensor(rng.standard_normal((3, 4, 2)), device=device)

    def by_hand(W0, x):
        return (mlp_jet([(W0, layers[0][1])] + layers[1:], x, dx)[1] * v).sum()

    def by_torch(W0, x):
        net = [(W0, layers[0][1])] + layers[1:]
        return sum((jvp(lambda u: mlp(net, u), (x,), (dx[k],))[1] * v[k]).sum() for k in range(3))

    for a, b in zip(jacrev(by_hand, argnums=(0, 1))(layers[0][0], x), jacrev(by_torch, argnums=(0, 1))(layers[0][0], x)):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-MLP")
def test_mlp_jet_gradcheck(device):
    rng = np.random.default_rng(1)
    params = {"layers": _layers(rng, [3, 5, 5, 2])}
    dx = rng.standard_normal((2, 4, 3))
    gradcheck_fn(lambda p, x, d: mlp_jet(p["layers"], x, d), (params, rng.standard_normal((4, 3)), dx),
                 diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-MLP")
def test_mlp_jet_rejects_bad_input():
    layers = [(torch.zeros(3, 4), torch.zeros(4)), (torch.zeros(4, 2), torch.zeros(2))]
    with pytest.raises(ValueError, match="^dx"):
        mlp_jet(layers, torch.zeros(5, 3), torch.zeros(2, 5, 2))
    with pytest.raises(ValueError, match="^dx"):
        mlp_jet(layers, torch.zeros(5, 3), torch.zeros(5, 3))
    with pytest.raises(ValueError, match="^x"):
        mlp_jet(layers, torch.zeros(5, 2), torch.zeros(1, 5, 2))
    with pytest.raises(ValueError, match="layers"):
        mlp_jet([], torch.zeros(5, 3), torch.zeros(1, 5, 3))
