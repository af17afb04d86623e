"""velogauss_ref.physics.acceleration: VG-ACC, a(x, t) = Phi(x) alpha(t, E(gamma(x))) with a
degree-ACC_POLY_DEGREE polynomial in t per motion pattern and its own column mask, and
VG-ACC-RIGID, a rigid body's acceleration per motion pattern, and VG-ACC-HARM, harmonics of
each oscillating pattern's frequency."""

import autograd.numpy as anp
import numpy as np
import pytest
from autograd import grad, jacobian
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, TRANSLATION_MASK, affine_matrix,
                                    constant_coefficient_params, flat_params, random_params, small_cfg)
from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_core.motion import init_motion_params
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import mixing_weights
from velogauss.scenes.trajectories import LinearFlowMotion, PeriodicFlowMotion
from velogauss_ref.physics.acceleration import acceleration_field, harmonic_patterns, rigid_patterns

seeds = st.integers(0, 2**32 - 1)
points = hnp.arrays(np.float64, (5, 3), elements=st.floats(-1.5, 1.5))


@pytest.mark.spec("VG-ACC")
@given(points, st.sampled_from([0.0, 2.0, -1.5]))
def test_polynomial_in_time(x, t):
    # Every pattern's alpha = g + c1 t + c2 t^2 on the translation columns: a(x, t) = alpha[:3].
    assert ACC_POLY_DEGREE == 2
    acc = np.zeros((3, 12))
    acc[0, :3] = [0.0, 0.0, -9.81]
    acc[1, :3] = [1.0, 0.0, 0.0]
    acc[2, :3] = [0.0, 0.5, 0.0]
    cfg = small_cfg()
    params = constant_coefficient_params(0, cfg, np.zeros(12), acc=acc)
    expected = np.broadcast_to([t, 0.5 * t * t, -9.81], (5, 3))
    np.testing.assert_allclose(acceleration_field(params, x, t, cfg), expected, rtol=0, atol=1e-13)
    zero = {**params, "acc": np.zeros_like(params["acc"])}
    np.testing.assert_array_equal(acceleration_field(zero, x, t, cfg), 0.0)


@pytest.mark.spec("VG-ACC")
@given(points, seeds)
def test_affine_in_x_like_the_velocity(x, seed):
    # alpha with every column set gives a = A(alpha) x + alpha[:3] (centripetal, strain, ...).
    acc = np.random.default_rng(seed).standard_normal((3, 12))
    t = 0.6
    alpha = acc[0] + acc[1] * t + acc[2] * t * t
    cfg = small_cfg()
    params = constant_coefficient_params(seed, cfg, np.zeros(12), acc=acc)
    np.testing.assert_allclose(acceleration_field(params, x, t, cfg), x @ affine_matrix(alpha).T + alpha[:3],
                               rtol=0, atol=1e-12)


@pytest.mark.spec("VG-ACC")
def test_acc_mask_not_mask_applies():
    # The velocity's mask must leave a alone; the acceleration's own mask cuts it.
    alpha = np.linspace(0.1, 1.2, 12)
    acc = np.zeros((3, 12))
    acc[0] = alpha
    x = np.random.default_rng(1).uniform(-1, 1, (5, 3))
    full = x @ affine_matrix(alpha).T + alpha[:3]
    translation_only = np.broadcast_to(alpha[:3], (5, 3))

    def a(**masks):
        cfg = small_cfg(**masks)
        return acceleration_field(constant_coefficient_params(1, cfg, np.zeros(12), acc=acc), x, 0.6, cfg)

    # A handful of roundings of O(1) values.
    np.testing.assert_allclose(a(mask=RIGID_MASK), full, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(mask=TRANSLATION_MASK), full, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(mask=RIGID_MASK, acc_mask=TRANSLATION_MASK), translation_only, rtol=0, atol=1e-13)
    np.testing.assert_allclose(a(acc_mask=TRANSLATION_MASK), translation_only, rtol=0, atol=1e-13)


@pytest.mark.spec("VG-ACC")
def test_time_derivative_at_t_zero_is_finite_and_exact():
    # d a / d t at t = 0 is Q_1 (through the mixture): t^0 must not contribute 0 * 0^-1 = NaN.
    acc = np.zeros((3, 12))
    acc[1, :3] = [0.3, -0.2, 0.1]
    cfg = small_cfg()
    params = constant_coefficient_params(0, cfg, np.zeros(12), acc=acc)
    x = np.random.default_rng(0).uniform(-1, 1, (2, 3))
    g = grad(lambda t: np.sum(acceleration_field(params, x, t, cfg)))(0.0)
    np.testing.assert_allclose(g, 2 * np.sum(acc[1, :3]), rtol=1e-14)


@pytest.mark.spec("VG-ACC")
@pytest.mark.parametrize("acc_masked", [False, True])
@settings(max_examples=10)
@given(seed=seeds, x=hnp.arrays(np.float64, (3, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-3, 3))
def test_acceleration_field_gradient(acc_masked, seed, x, t):
    cfg = small_cfg(acc_mask=TRANSLATION_MASK if acc_masked else None)
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, x, t: acceleration_field(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.parametrize(
    "x, t, acc, name",
    [
        (np.zeros((2, 2)), 0.1, None, "x"),
        (np.full((2, 3), np.nan), 0.1, None, "x"),
        (np.zeros((2, 3)), -np.inf, None, "t"),
        (np.zeros((2, 3)), 0.1, np.zeros((2, 4, 12)), r'params\["acc"\]'),
        (np.zeros((2, 3)), 0.1, np.full((3, 4, 12), np.nan), r'params\["acc"\]'),
    ],
)
def test_bad_input_names_the_argument(x, t, acc, name):
    cfg = small_cfg()
    params = random_params(0, cfg)
    if acc is not None:
        params["acc"] = acc
    with pytest.raises(ValueError, match=f"^{name}:"):
        acceleration_field(params, x, t, cfg)


# --- VG-ACC-RIGID ------------------------------------------------------------------------

def _rigid_params(seed, cfg, R):
    """Parameters whose every motion pattern has the rigid acceleration row R (12,): any
    softmax mixture of the patterns then gives R's field."""
    return {**random_params(seed, cfg), "acc": np.tile(np.asarray(R, dtype=np.float64), (cfg.n_patterns, 1))}


vectors = hnp.arrays(np.float64, (3,), elements=st.floats(-2, 2))


@pytest.mark.spec("VG-ACC-RIGID")
@settings(max_examples=25)
@given(omega=vectors, g=vectors, c0=vectors, u=vectors, x=points, t=st.floats(-2, 3))
def test_rigid_form_is_the_material_acceleration_of_a_spinning_falling_body(omega, g, c0, u, x, t):
    # Oracle: the velocity of a body spinning at omega about a centre c(t) = c0 + u t + g t^2 / 2,
    # v(x, t) = omega x (x - c(t)) + c'(t), differentiated by autograd: Dv/Dt = dv/dt + (grad v) v.
    def v(y, s):
        c = c0 + u * s + 0.5 * g * s * s
        return anp.cross(omega, y - c) + u + g * s

    expected = np.array([jacobian(lambda s: v(xi, s))(t) + jacobian(lambda y: v(y, t))(xi) @ v(xi, t)
                         for xi in x])
    cfg = small_cfg(acc_form="rigid")
    got = acceleration_field(_rigid_params(0, cfg, np.concatenate([omega, g, c0, u])), x, t, cfg)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))


@pytest.mark.spec("VG-ACC-RIGID")
def test_rigid_patterns_by_hand():
    # omega = (0, 0, 2): Omega^2 = diag(-4, -4, 0); g = (0, 0, -8), centre at rest at (1, 0, 0) at t = 0.
    R = np.array([[0, 0, 2, 0, 0, -8, 1, 0, 0, 0, 0, 0]], dtype=np.float64)
    t = 0.5  # c = (1, 0, -1): g - Omega^2 c = (4, 0, -8)
    np.testing.assert_array_equal(rigid_patterns(R, t), [[4, 0, -8, 0, 0, 0, -4, -4, 0, 0, 0, 0]])
    np.testing.assert_array_equal(rigid_patterns(np.zeros((3, 12)), t), np.zeros((3, 12)))


@pytest.mark.spec("VG-ACC-RIGID")
@settings(max_examples=10)
@given(seed=seeds, t=st.floats(-3, 3))
def test_rigid_patterns_gradient(seed, t):
    R = np.random.default_rng(seed).standard_normal((4, 12))
    check_grads_fd(rigid_patterns, (R, t), (0, 1), np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.spec("VG-ACC-RIGID")
@settings(max_examples=10)
@given(seed=seeds, x=hnp.arrays(np.float64, (3, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-3, 3))
def test_rigid_acceleration_field_gradient(seed, x, t):
    cfg = small_cfg(acc_form="rigid")
    params = random_params(seed, cfg)
    assert params["acc"].shape == (cfg.n_patterns, 12)
    theta, unflatten = flat_params(params)
    check_grads_fd(lambda theta, x, t: acceleration_field(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


def test_rigid_form_checks_the_shape_of_its_parameters():
    cfg = small_cfg(acc_form="rigid")
    params = {**random_params(0, cfg), "acc": np.zeros((3, cfg.n_patterns, 12))}  # a polynomial's Q
    with pytest.raises(ValueError, match=r'^params\["acc"\]:'):
        acceleration_field(params, np.zeros((2, 3)), 0.1, cfg)


def test_fresh_rigid_parameters_have_a_spin_to_differentiate():
    # Omega^2 is quadratic in omega: at omega = 0 its gradient is zero and the spin never learns.
    cfg = small_cfg(acc_form="rigid")
    R = init_motion_params(np.random.default_rng(0), cfg)["acc"]
    assert R.shape == (cfg.n_patterns, 12) and np.all(R[:, 3:] == 0)
    assert np.all(np.linalg.norm(R[:, :3], axis=1) > 0)
    d = grad(lambda R: np.sum(rigid_patterns(R, 0.3)[:, 6:] ** 2))(R)
    assert np.abs(d[:, :3]).max() > 0


@pytest.mark.spec("VG-ACC-RIGID")
@settings(max_examples=10)
@given(seed=seeds, x=points, t=st.floats(-2, 3))
def test_rigid_form_mixes_the_bodies_not_their_accelerations(seed, x, t):
    # Every point follows one rigid body, B = m(z) R: its acceleration, written by hand with
    # cross products, is g + omega x (omega x (x - c(t))) of the mixed parameters.
    cfg = small_cfg(acc_form="rigid")
    params = random_params(seed, cfg, scale=3.0)
    B = mixing_weights(params, physics_code(params, x, cfg)) @ params["acc"]
    omega, g, c0, u = B[:, 0:3], B[:, 3:6], B[:, 6:9], B[:, 9:12]
    c = c0 + u * t + 0.5 * g * t * t
    expected = g + np.cross(omega, np.cross(omega, x - c))
    got = acceleration_field(params, x, t, cfg)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))


@pytest.mark.spec("VG-ACC-HARM")
@settings(max_examples=10)
@given(x=points, t=st.floats(-1, 3))
def test_harmonic_form_is_the_material_acceleration_of_a_pulsing_body(x, t):
    # Oracle: velogauss.scenes' periodic flow, whose material acceleration is
    # w^2 (cos^2(w t) L^2 - sin(w t) L)(x - c) = w^2 ((1 + cos 2wt) / 2 L^2 - sin(wt) L)(x - c):
    # harmonics 0, 1 and 2 of w. The basis coefficients of a field M (x - c) are those of a
    # linear flow with generator M at t = 0. Written about the patterns' centres (VG-COEF-CENTRE)
    # at c, they are the flow's about the origin.
    L = np.array([[0.2, 0.0, 0.6], [0.0, -0.4, 0.1], [0.6, 0.1, 0.2]])
    centre, w = (0.3, -0.2, 0.1), 3 * np.pi
    body = PeriodicFlowMotion(centre=centre, generator=L, omega=w)
    cfg = small_cfg(pattern_form="harmonic", acc_form="harmonic")
    params = random_params(0, cfg)
    params["time"] = [(params["time"][0][0], np.array([w]))]
    expected = body.acceleration(x, t)
    for about in ((0.0, 0.0, 0.0), centre):
        shifted = np.subtract(centre, about)
        of = lambda M: LinearFlowMotion(centre=shifted, generator=M).basis_coefficients(0.0)  # noqa: E731
        Q = w * w * np.stack([of(L @ L) / 2, np.zeros(12), -of(L), of(L @ L) / 2, np.zeros(12)])
        params["acc"] = np.tile(Q[:, None, :], (1, cfg.n_patterns, 1))
        params["centre"] = np.tile(about, (cfg.n_patterns, 1))
        got = acceleration_field(params, x, t, cfg)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * (1 + np.abs(expected).max()))


@pytest.mark.spec("VG-ACC-HARM")
def test_harmonic_patterns_by_hand():
    # Omega t = pi / 2: phi = (1, cos, sin, cos 2, sin 2) = (1, 0, 1, -1, 0).
    Q = np.arange(5 * 2 * 12, dtype=np.float64).reshape(5, 2, 12)
    omega = np.array([2 * np.pi])
    np.testing.assert_allclose(harmonic_patterns(Q, omega, 0.25), Q[0] + Q[2] - Q[3], rtol=0, atol=1e-12)


@pytest.mark.spec("VG-ACC-HARM")
@settings(max_examples=10)
@given(seed=seeds, x=hnp.arrays(np.float64, (3, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-3, 3))
def test_harmonic_acceleration_field_gradient(seed, x, t):
    # The frequency sits in params["time"]: the gradient reaches it through both fields.
    cfg = small_cfg(pattern_form="harmonic", acc_form="harmonic")
    params = random_params(seed, cfg)
    assert params["acc"].shape == (5, cfg.n_patterns, 12)
    theta, unflatten = flat_params(params)
    check_grads_fd(lambda theta, x, t: acceleration_field(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)
