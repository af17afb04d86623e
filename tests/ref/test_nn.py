"""velogauss_ref.nn: VG-ENC (positional encoding) and VG-MLP (silu MLP, linear last layer)."""

import math

import numpy as np
import pytest
from autograd import make_vjp
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import FD_STEP, flat_params
from velogauss_ref.nn import mlp, positional_encoding

# Identities of O(1) float64 values through a few roundings (sin/cos are correctly rounded
# to within an ulp or two).
TOL = 1e-14

seeds = st.integers(0, 2**32 - 1)


def _layers(rng, dims):
    return [(rng.standard_normal((a, b)) / np.sqrt(a), rng.standard_normal(b)) for a, b in zip(dims[:-1], dims[1:])]


def _silu(u):
    """silu written the textbook way, independently of velogauss_ref.nn (valid for |u| < 700)."""
    return u / (1.0 + np.exp(-u))


@pytest.mark.spec("VG-ENC")
def test_encoding_known_values():
    g = positional_encoding(np.array([[0.5, 0.25]]), 2)
    s = math.sqrt(0.5)
    # [x, sin(pi x), cos(pi x), sin(2 pi x), cos(2 pi x)], each block D = 2 wide.
    np.testing.assert_allclose(g[0], [0.5, 0.25, 1.0, s, 0.0, s, 0.0, 1.0, -1.0, 0.0], rtol=0, atol=TOL)


@pytest.mark.spec("VG-ENC")
@given(hnp.arrays(np.float64, st.sampled_from([(4, 3), (2, 3, 1), (0, 3), (5,)]), elements=st.floats(-3, 3)),
       st.integers(0, 5))
def test_encoding_blocks_and_shapes(x, n_freqs):
    g = positional_encoding(x, n_freqs)
    D = x.shape[-1]
    assert g.shape == x.shape[:-1] + (D * (1 + 2 * n_freqs),)
    np.testing.assert_array_equal(g[..., :D], x)
    for k in range(n_freqs):
        start = D * (1 + 2 * k)
        np.testing.assert_allclose(g[..., start:start + D], np.sin(2.0**k * np.pi * x), rtol=0, atol=1e-12)
        np.testing.assert_allclose(g[..., start + D:start + 2 * D], np.cos(2.0**k * np.pi * x), rtol=0, atol=1e-12)


@pytest.mark.spec("VG-ENC")
def test_encoding_with_no_frequencies_is_the_input():
    x = np.random.default_rng(0).standard_normal((3, 2))
    np.testing.assert_array_equal(positional_encoding(x, 0), x)


@pytest.mark.spec("VG-ENC")
@given(hnp.arrays(np.float64, (3, 2), elements=st.floats(-2, 2)), st.integers(0, 4), seeds)
def test_encoding_gradient(x, n_freqs, seed):
    check_grads_fd(lambda x: positional_encoding(x, n_freqs), (x,), (0,), np.random.default_rng(seed))


@pytest.mark.spec("VG-MLP")
def test_mlp_is_affine_then_silu_then_linear():
    W0, b0 = np.array([[1.0, -2.0]]), np.array([0.5, 0.0])
    W1, b1 = np.array([[3.0], [1.0]]), np.array([-1.0])
    h = _silu(np.array([0.7 + 0.5, -1.4]))
    np.testing.assert_allclose(mlp([(W0, b0), (W1, b1)], np.array([[0.7]])), [[3 * h[0] + h[1] - 1]], rtol=TOL)
    # A single layer is linear: no activation after the last layer.
    np.testing.assert_allclose(mlp([(W1, b1)], np.array([[-5.0, 2.0]])), [[-15.0 + 2.0 - 1.0]], rtol=TOL)


@pytest.mark.spec("VG-MLP")
@given(seeds, st.integers(1, 4), st.sampled_from([(5,), (2, 3), (0,)]))
def test_mlp_matches_a_plain_numpy_forward_pass(seed, depth, batch):
    rng = np.random.default_rng(seed)
    layers = _layers(rng, [4] + [6] * (depth - 1) + [3])
    x = rng.uniform(-2, 2, batch + (4,))
    h = x
    for W, b in layers[:-1]:
        h = _silu(h @ W + b)
    expected = h @ layers[-1][0] + layers[-1][1]
    out = mlp(layers, x)
    assert out.shape == batch + (3,)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-MLP")
def test_silu_saturates_without_overflow():
    # Pre-activations of +-1e4: silu(u) = u for large u and 0 for very negative u, and the
    # derivative (1 and 0) stays finite where 1 / (1 + exp(-u)) would overflow.
    layers = [(np.array([[1.0, -1.0]]), np.zeros(2)), (np.array([[1.0], [1.0]]), np.zeros(1))]
    x = np.array([[1e4], [-1e4]])
    vjp, y = make_vjp(lambda p, x: mlp(p, x), argnum=(0, 1))(layers, x)
    np.testing.assert_array_equal(y, [[1e4], [1e4]])
    grads = vjp(np.ones_like(y))
    assert all(np.all(np.isfinite(g)) for pair in grads[0] for g in pair) and np.all(np.isfinite(grads[1]))
    np.testing.assert_array_equal(grads[1], [[1.0], [-1.0]])


@pytest.mark.spec("VG-MLP")
@given(seeds, st.integers(1, 3))
def test_mlp_gradient(seed, depth):
    rng = np.random.default_rng(seed)
    layers = _layers(rng, [3] + [5] * (depth - 1) + [2])
    theta, unflatten = flat_params(layers)
    x = rng.uniform(-2, 2, (4, 3))
    check_grads_fd(lambda theta, x: mlp(unflatten(theta), x), (theta, x), (0, 1), rng, step=FD_STEP)


@pytest.mark.parametrize("n_freqs", [-1, 1.5, True, None])
def test_encoding_rejects_bad_n_freqs(n_freqs):
    with pytest.raises(ValueError, match="^n_freqs:"):
        positional_encoding(np.zeros((2, 3)), n_freqs)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: positional_encoding(np.array([[0.0, np.nan, 1.0]]), 2), "x"),
        (lambda: positional_encoding(np.array(1.0), 2), "x"),
        (lambda: mlp([], np.zeros((5, 3))), "layers"),
        (lambda: mlp([(np.zeros((3, 4)), np.zeros(4))], np.zeros((5, 2))), "x"),
        (lambda: mlp([(np.zeros((3, 4)), np.zeros(4))], np.full((5, 3), np.inf)), "x"),
        (lambda: mlp([(np.zeros((3, 4)), np.zeros(3))], np.zeros((5, 3))), r"layers\[0\]\.b"),
        (lambda: mlp([(np.zeros((3, 4)), np.zeros(4)), (np.zeros((5, 2)), np.zeros(2))], np.zeros((5, 3))),
         r"layers\[1\]\.W"),
        (lambda: mlp([(np.full((3, 4), np.nan), np.zeros(4))], np.zeros((5, 3))), r"layers\[0\]\.W"),
    ],
)
def test_bad_input_names_the_argument(call, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        call()
