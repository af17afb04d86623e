"""velogauss_ref.physics.acceleration: VG-ACC, a(x, t) = Phi(x) alpha(t, E(gamma(x))) with a
degree-ACC_POLY_DEGREE polynomial in t per motion pattern and its own column mask."""

import numpy as np
import pytest
from autograd import grad
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, TRANSLATION_MASK, affine_matrix,
                                    constant_coefficient_params, flat_params, random_params, small_cfg)
from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_ref.physics.acceleration import acceleration_field

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
