"""velogauss_ref.physics.residuals: VG-TRANSPORT (r = dv/dt + (grad v) v - a) and VG-DIV
(div v), with every derivative of the Eulerian field taken by autograd, against closed forms
and finite differences."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, affine_matrix, constant_coefficient_params, flat_params,
                                    mlp_velocity_params, random_params, small_cfg)
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.motion.velocity import mlp_velocity, velocity_field
from velogauss_ref.physics.acceleration import acceleration_field
from velogauss_ref.physics.residuals import divergence, mlp_residuals, transport_residual, velocity_derivatives

seeds = st.integers(0, 2**32 - 1)
points = hnp.arrays(np.float64, (4, 3), elements=st.floats(-1.5, 1.5))


def _centripetal(omega, b):
    """alpha (12,) with Phi(x) alpha = Omega (Omega x + b), the material acceleration of v = omega x x + b.

    Omega^2 = omega omega^T - |omega|^2 I is symmetric: stretch (diagonal) and shear columns.
    """
    M = np.outer(omega, omega) - (omega @ omega) * np.eye(3)
    alpha = np.zeros(12)
    alpha[0:3] = np.cross(omega, b)
    alpha[6:9] = np.diag(M)
    alpha[9:12] = [M[0, 1], M[1, 2], M[0, 2]]
    return alpha


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV")
@settings(max_examples=10)
@given(seeds, points)
def test_constant_coefficients_jacobian_is_A(seed, x):
    # Constant w: grad v = A(w) exactly (the code's x-dependence has no effect), dv/dt = 0,
    # div v = w7 + w8 + w9, curl v = 2 omega, r = A (A x + b) - a.
    rng = np.random.default_rng(seed)
    w, acc = rng.standard_normal(12), rng.standard_normal((3, 12))
    cfg = small_cfg()
    params = constant_coefficient_params(seed, cfg, w, acc=acc)
    t = 0.3
    A = affine_matrix(w)
    dv_dt, grad_v = velocity_derivatives(params, x, t, cfg)
    # Roundings of O(1) values through the softmax mixture and a few products.
    np.testing.assert_allclose(grad_v, np.broadcast_to(A, (4, 3, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(dv_dt, 0.0, rtol=0, atol=1e-12)
    curl = np.stack([grad_v[:, 2, 1] - grad_v[:, 1, 2], grad_v[:, 0, 2] - grad_v[:, 2, 0],
                     grad_v[:, 1, 0] - grad_v[:, 0, 1]], axis=-1)
    np.testing.assert_allclose(curl, np.broadcast_to(2 * w[3:6], (4, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(divergence(params, x, t, cfg), w[6] + w[7] + w[8], rtol=0, atol=1e-12)
    alpha = acc[0] + acc[1] * t + acc[2] * t * t
    expected = (x @ A.T + w[:3]) @ A.T - (x @ affine_matrix(alpha).T + alpha[:3])
    np.testing.assert_allclose(transport_residual(params, x, t, cfg), expected, rtol=0, atol=1e-11)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV", "VG-ACC")
@given(points, seeds)
def test_rigid_rotation_is_divergence_free_and_balanced_by_the_centripetal_acceleration(x, seed):
    # v = omega x x + b under the rigid velocity mask; a = Omega (Omega x + b) needs the
    # acceleration's wider mask (here all columns) and makes the transport residual vanish.
    rng = np.random.default_rng(seed)
    omega, b = rng.standard_normal(3), rng.standard_normal(3)
    w = np.concatenate([b, omega, np.zeros(6)])
    acc = np.zeros((3, 12))
    acc[0] = _centripetal(omega, b)
    cfg = small_cfg(mask=RIGID_MASK)
    params = constant_coefficient_params(seed, cfg, w, acc=acc)
    # Roundings of O(1) values (|omega|, |b| ~ 1, |x| < 2.6) through two products.
    np.testing.assert_allclose(transport_residual(params, x, 0.7, cfg), 0.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(divergence(params, x, 0.7, cfg), 0.0, rtol=0, atol=1e-12)
    # Without acceleration the residual is the centripetal term itself.
    still = {**params, "acc": np.zeros_like(params["acc"])}
    M = np.outer(omega, omega) - (omega @ omega) * np.eye(3)
    np.testing.assert_allclose(transport_residual(still, x, 0.7, cfg), x @ M.T + np.cross(omega, b), rtol=0,
                               atol=1e-12)


@pytest.mark.spec("VG-TRANSPORT")
@given(points, seeds, st.sampled_from([0.0, 0.45, -2.0]))
def test_coefficients_linear_in_time(x, seed, t):
    # A one-layer time network on raw t (n_freqs_t = 0) with equal patterns gives
    # w(t) = w0 + t w1: dv/dt = A(w1) x + b(w1) and grad v = A(w(t)), so
    # r = A(w1) x + b(w1) + A(w)(A(w) x + b(w)) with a = 0.
    rng = np.random.default_rng(seed)
    w0, w1 = rng.standard_normal(12), rng.standard_normal(12)
    cfg = small_cfg(n_freqs_t=0)
    params = random_params(seed, cfg)
    K = cfg.n_patterns
    params["time"] = [(np.tile(w1, K)[None, :], np.tile(w0, K))]
    params["acc"] = np.zeros_like(params["acc"])
    params["centre"] = np.zeros_like(params["centre"])  # the world-frame field (VG-COEF-CENTRE)
    w = w0 + t * w1
    A, A1 = affine_matrix(w), affine_matrix(w1)
    expected = x @ A1.T + w1[:3] + (x @ A.T + w[:3]) @ A.T
    np.testing.assert_allclose(transport_residual(params, x, t, cfg), expected, rtol=0, atol=1e-11)


@pytest.mark.spec("VG-TRANSPORT", "VG-DIV", "VG-FIELD")
@settings(max_examples=5)
@given(seeds, points)
def test_derivatives_include_the_code_and_match_finite_differences(seed, x):
    # Random networks: the code E(gamma(x)) varies with x, so grad v differs from A(w(x)).
    # Central differences of VG-FIELD itself (Richardson-extrapolated, h = 1e-4: truncation
    # ~h^4 ~ 1e-16, rounding ~1e-16 / h ~ 1e-12) are an independent oracle.
    cfg = small_cfg()
    params = random_params(seed, cfg)
    t = 0.35
    dv_dt, grad_v = velocity_derivatives(params, x, t, cfg)

    def central(f, h=1e-4):
        d = lambda h: (f(h) - f(-h)) / (2 * h)  # noqa: E731
        return (4 * d(h / 2) - d(h)) / 3

    for j in range(3):
        e = np.zeros(3)
        e[j] = 1.0
        fd = central(lambda h: velocity_field(params, x + h * e, t, cfg))
        np.testing.assert_allclose(grad_v[:, :, j], fd, rtol=0, atol=1e-9 * (1 + np.abs(fd).max()))
    fd_t = central(lambda h: velocity_field(params, x, t + h, cfg))
    np.testing.assert_allclose(dv_dt, fd_t, rtol=0, atol=1e-9 * (1 + np.abs(fd_t).max()))
    np.testing.assert_allclose(divergence(params, x, t, cfg), np.trace(grad_v, axis1=1, axis2=2), rtol=0, atol=0)
    # The code's share of grad v is not negligible here, so the comparison above pins it.
    w = coefficients(params, t, physics_code(params, x, cfg), cfg)
    assert max(np.abs(grad_v[n] - affine_matrix(w[n])).max() for n in range(len(x))) > 1e-3


@pytest.mark.spec("VG-TRANSPORT")
@pytest.mark.parametrize("masked", [False, True])
@settings(max_examples=4)
@given(seed=seeds, x=hnp.arrays(np.float64, (2, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-2, 2))
def test_transport_residual_gradient(masked, seed, x, t):
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, x, t: transport_residual(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.spec("VG-DIV")
@settings(max_examples=4)
@given(seed=seeds, x=hnp.arrays(np.float64, (2, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-2, 2))
def test_divergence_gradient(seed, x, t):
    cfg = small_cfg()
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, x, t: divergence(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.parametrize("fn", [transport_residual, divergence])
@pytest.mark.parametrize(
    "x, t, name",
    [
        (np.zeros((2, 4)), 0.1, "x"),
        (np.full((2, 3), np.nan), 0.1, "x"),
        (np.zeros((2, 3)), np.nan, "t"),
        (np.zeros((2, 3)), np.zeros(1), "t"),
    ],
)
def test_bad_input_names_the_argument(fn, x, t, name):
    cfg = small_cfg()
    with pytest.raises(ValueError, match=f"^{name}:"):
        fn(random_params(0, cfg), x, t, cfg)


@pytest.mark.spec("VG-TRANSPORT-MLP")
@pytest.mark.parametrize("seed", [0, 1])
def test_mlp_residuals_against_finite_differences(seed):
    # dv/dt, (grad v) v and div v of the MLP velocity by central differences (step 1e-5:
    # truncation ~1e-10 and rounding ~1e-11 on these O(1) smooth networks), against the
    # residuals autograd gives; the acceleration term is VG-ACC's field, as with PDS.
    cfg = small_cfg()
    params = mlp_velocity_params(seed, cfg)
    x = np.random.default_rng(seed).uniform(-1.2, 1.2, (4, 3))
    t, h = 0.35, 1e-5
    v = mlp_velocity(params, x, t, cfg)
    dv_dt = (mlp_velocity(params, x, t + h, cfg) - mlp_velocity(params, x, t - h, cfg)) / (2 * h)
    grad_v = np.stack([(mlp_velocity(params, x + h * e, t, cfg) - mlp_velocity(params, x - h * e, t, cfg)) / (2 * h)
                       for e in np.eye(3)], axis=-1)  # [n, i, j] = dv_i / dx_j
    expected = dv_dt + np.einsum("nij,nj->ni", grad_v, v) - acceleration_field(params, x, t, cfg)
    r, div = mlp_residuals(params, x, t, cfg, with_divergence=True)
    np.testing.assert_allclose(r, expected, rtol=0, atol=1e-7 * np.abs(expected).max())
    np.testing.assert_allclose(div, np.trace(grad_v, axis1=1, axis2=2), rtol=0, atol=1e-7)
    r_only, none = mlp_residuals(params, x, t, cfg)
    assert none is None
    np.testing.assert_array_equal(r_only, r)
