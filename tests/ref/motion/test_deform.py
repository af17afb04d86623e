"""velogauss_ref.motion.deform: VG-ADF (residual deformation field) and VG-ADF-COMPOSE."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import FD_STEP, flat_outputs, flat_params, random_params, small_cfg
from velogauss_ref.motion.deform import adf_residual, compose_state
from velogauss_ref.quaternion import quat_to_rotmat

seeds = st.integers(0, 2**32 - 1)
quats = hnp.arrays(np.float64, (4, 4), elements=st.floats(-2, 2)).filter(lambda q: np.all(np.sum(q * q, axis=1) >= 0.1))


def _gamma(x, n_freqs):
    """gamma written out with plain NumPy (VG-ENC)."""
    blocks = [x]
    for k in range(n_freqs):
        blocks += [np.sin(2.0**k * np.pi * x), np.cos(2.0**k * np.pi * x)]
    return np.concatenate(blocks, axis=-1)


@pytest.mark.spec("VG-ADF")
@given(seeds, st.sampled_from([0.0, 0.8, -4.0]))
def test_outputs_are_the_slices_of_one_network(seed, t):
    # A one-layer (linear) ADF makes o an explicit product: o = [gamma(x0), gamma(t), z] W + b.
    cfg = small_cfg()
    rng = np.random.default_rng(seed)
    x0, z = rng.uniform(-1, 1, (4, 3)), rng.standard_normal((4, cfg.code_dim))
    features = np.concatenate([_gamma(x0, cfg.n_freqs_adf_x), np.tile(_gamma(np.array([t]), cfg.n_freqs_adf_t), (4, 1)),
                               z], axis=1)
    W, b = rng.standard_normal((features.shape[1], 10)), rng.standard_normal(10)
    params = {**random_params(seed, cfg), "adf": [(W, b)]}
    o = features @ W + b
    dx, dq, ds = adf_residual(params, x0, t, z, cfg)
    np.testing.assert_allclose(dx, o[:, 0:3], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dq, o[:, 3:7] + [1.0, 0.0, 0.0, 0.0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ds, o[:, 7:10], rtol=1e-12, atol=1e-12)


@pytest.mark.spec("VG-ADF", "VG-ADF-COMPOSE")
def test_zero_last_layer_is_the_identity():
    cfg = small_cfg()
    params = random_params(0, cfg)
    W, b = params["adf"][-1]
    params["adf"][-1] = (np.zeros_like(W), np.zeros_like(b))
    rng = np.random.default_rng(0)
    x0, z = rng.uniform(-1, 1, (4, 3)), rng.standard_normal((4, cfg.code_dim))
    dx, dq, ds = adf_residual(params, x0, 0.3, z, cfg)
    np.testing.assert_array_equal(dx, 0.0)
    np.testing.assert_array_equal(ds, 0.0)
    np.testing.assert_array_equal(dq, np.tile([1.0, 0.0, 0.0, 0.0], (4, 1)))
    q_star, s_star = rng.standard_normal((4, 4)), rng.uniform(0.1, 1, (4, 3))
    x, q, s = compose_state(x0, q_star, s_star, dx, dq, ds)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_array_equal(s, s_star)
    np.testing.assert_allclose(q, q_star / np.linalg.norm(q_star, axis=1, keepdims=True), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-ADF-COMPOSE")
@given(quats, quats, seeds)
def test_compose_state_semantics(q_star, dq, seed):
    rng = np.random.default_rng(seed)
    x_star, dx = rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
    s_star, ds = rng.uniform(0.01, 2, (4, 3)), rng.standard_normal((4, 3))
    x, q, s = compose_state(x_star, q_star, s_star, dx, dq, ds)
    np.testing.assert_array_equal(x, x_star + dx)
    np.testing.assert_allclose(s, s_star * np.exp(ds), rtol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=0, atol=1e-15)
    # R(q* (x) dq) = R(q*) R(dq): the correction acts in the base state's frame, after it.
    np.testing.assert_allclose(quat_to_rotmat(q), quat_to_rotmat(q_star) @ quat_to_rotmat(dq), rtol=0, atol=1e-13)


@pytest.mark.spec("VG-ADF")
@settings(max_examples=10)
@given(seed=seeds, t=st.floats(-4, 4), n_freqs_adf_t=st.integers(0, 2))
def test_adf_residual_gradient(seed, t, n_freqs_adf_t):
    cfg = small_cfg(n_freqs_adf_t=n_freqs_adf_t)
    rng = np.random.default_rng(seed)
    theta, unflatten = flat_params(random_params(seed, cfg))
    x0, z = rng.uniform(-1, 1, (3, 3)), rng.standard_normal((3, cfg.code_dim))
    f = flat_outputs(lambda theta, x0, t, z: adf_residual(unflatten(theta), x0, t, z, cfg))
    check_grads_fd(f, (theta, x0, t, z), (0, 1, 2, 3), rng, step=FD_STEP)


@pytest.mark.spec("VG-ADF-COMPOSE")
@given(quats, quats, seeds)
def test_compose_state_gradient(q_star, dq, seed):
    rng = np.random.default_rng(seed)
    args = (rng.standard_normal((4, 3)), q_star, rng.uniform(0.1, 1, (4, 3)), rng.standard_normal((4, 3)), dq,
            rng.standard_normal((4, 3)))
    check_grads_fd(flat_outputs(compose_state), args, tuple(range(6)), rng)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda p, c: adf_residual(p, np.zeros((3, 3)), 0.1, np.zeros((2, 3)), c), "z"),
        (lambda p, c: adf_residual(p, np.zeros((3, 3)), np.nan, np.zeros((3, 3)), c), "t"),
        (lambda p, c: adf_residual(p, np.zeros((3, 2)), 0.1, np.zeros((3, 3)), c), "x0"),
        (lambda p, c: adf_residual(p, np.full((3, 3), np.inf), 0.1, np.zeros((3, 3)), c), "x0"),
        (lambda p, c: compose_state(np.zeros((3, 3)), np.ones((3, 4)), np.ones((3, 3)), np.zeros((3, 3)),
                                    np.ones((2, 4)), np.zeros((3, 3))), "dq"),
        (lambda p, c: compose_state(np.zeros((3, 3)), np.ones((3, 4)), np.ones((3, 3)), np.zeros((3, 3)),
                                    np.ones((3, 4)), np.full((3, 3), np.inf)), "ds"),
        (lambda p, c: compose_state(np.zeros((3, 3)), np.ones((3, 3)), np.ones((3, 3)), np.zeros((3, 3)),
                                    np.ones((3, 4)), np.zeros((3, 3))), "q_star"),
        (lambda p, c: compose_state(np.zeros((3, 3)), np.ones((3, 4)), np.full((3, 3), np.nan), np.zeros((3, 3)),
                                    np.ones((3, 4)), np.zeros((3, 3))), "s_star"),
    ],
)
def test_bad_input_names_the_argument(call, name):
    cfg = small_cfg()
    with pytest.raises(ValueError, match=f"^{name}:"):
        call(random_params(0, cfg), cfg)
