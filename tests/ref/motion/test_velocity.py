"""velogauss_ref.motion.velocity: VG-VEL (v = Phi(x) w) and VG-FIELD (the Eulerian field v(x, t))."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, affine_matrix, constant_coefficient_params, flat_params,
                                    mlp_velocity_params, random_params, small_cfg)
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.motion.velocity import mlp_velocity, velocity, velocity_field

# Sums of a few O(1) float64 products.
TOL = 1e-13

seeds = st.integers(0, 2**32 - 1)
points = hnp.arrays(np.float64, (5, 3), elements=st.floats(-1.5, 1.5))
coeffs = hnp.arrays(np.float64, (5, 12), elements=st.floats(-3, 3))


@pytest.mark.spec("VG-VEL")
@given(points, coeffs)
def test_velocity_is_affine_in_x(x, w):
    expected = np.stack([affine_matrix(w[n]) @ x[n] + w[n, :3] for n in range(len(x))])
    np.testing.assert_allclose(velocity(x, w), expected, rtol=0, atol=TOL)


@pytest.mark.spec("VG-VEL")
def test_pure_translation_and_spin():
    x = np.array([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    w = np.zeros((2, 12))
    w[0, 0:3] = [0.5, -1.0, 2.0]  # translation: v = b everywhere
    w[1, 5] = 3.0  # spin about z: v = omega x x = (-3 y, 3 x, 0)
    np.testing.assert_array_equal(velocity(x, w), [[0.5, -1.0, 2.0], [-6.0, 0.0, 0.0]])


@pytest.mark.spec("VG-FIELD")
@given(seeds, points, st.sampled_from([0.0, 0.6, -3.0, 12.0]))
def test_field_takes_the_code_at_the_query_point(seed, x, t):
    cfg = small_cfg()
    params = random_params(seed, cfg)
    w = coefficients(params, t, physics_code(params, x, cfg), cfg)
    np.testing.assert_array_equal(velocity_field(params, x, t, cfg), velocity(x, w))


@pytest.mark.spec("VG-FIELD")
@given(seeds, points)
def test_constant_coefficients_give_the_affine_field(seed, x):
    w = np.random.default_rng(seed).standard_normal(12)
    cfg = small_cfg()
    params = constant_coefficient_params(seed, cfg, w)
    A = affine_matrix(w)
    # The softmax mixture of K equal patterns returns w up to a few roundings.
    np.testing.assert_allclose(velocity_field(params, x, 0.3, cfg), x @ A.T + w[:3], rtol=0, atol=1e-12)


@pytest.mark.spec("VG-VEL")
@given(points, coeffs, seeds)
def test_velocity_gradient(x, w, seed):
    check_grads_fd(velocity, (x, w), (0, 1), np.random.default_rng(seed))


# The Eulerian field (masked or not) and the no-pds MLP velocity, by the same gradient check.
FIELDS = [
    pytest.param(velocity_field, random_params, None, marks=pytest.mark.spec("VG-FIELD"), id="field"),
    pytest.param(velocity_field, random_params, RIGID_MASK, marks=pytest.mark.spec("VG-FIELD"), id="field-masked"),
    pytest.param(mlp_velocity, mlp_velocity_params, None, marks=pytest.mark.spec("VG-VEL-MLP"), id="mlp"),
]


@pytest.mark.parametrize("field, draw_params, mask", FIELDS)
@given(seed=seeds, x=hnp.arrays(np.float64, (3, 3), elements=st.floats(-1.5, 1.5)), t=st.floats(-3, 3))
def test_velocity_field_gradient(field, draw_params, mask, seed, x, t):
    cfg = small_cfg(mask=mask)
    theta, unflatten = flat_params(draw_params(seed, cfg))
    check_grads_fd(lambda theta, x, t: field(unflatten(theta), x, t, cfg), (theta, x, t), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda p, c: velocity(np.zeros((3, 3)), np.zeros((4, 12))), "w"),
        (lambda p, c: velocity(np.zeros((3, 4)), np.zeros((3, 12))), "x"),
        (lambda p, c: velocity(np.zeros((3, 3)), np.full((3, 12), np.nan)), "w"),
        (lambda p, c: velocity_field(p, np.zeros((2, 3)), np.inf, c), "t"),
        (lambda p, c: velocity_field(p, np.full((2, 3), np.nan), 0.0, c), "x"),
        (lambda p, c: velocity_field(p, np.zeros((2, 2)), 0.0, c), "x"),
    ],
)
def test_bad_input_names_the_argument(call, name):
    cfg = small_cfg()
    with pytest.raises(ValueError, match=f"^{name}:"):
        call(random_params(0, cfg), cfg)


@pytest.mark.spec("VG-VEL-MLP")
def test_mlp_velocity_is_the_mlp_of_encoded_position_and_time():
    # Written out by hand for one point: gamma(x) with cfg.n_freqs_x frequencies, then t,
    # through silu hidden layers and a linear last layer.
    cfg = small_cfg()
    params = mlp_velocity_params(2, cfg)
    x, t = np.array([[0.3, -0.7, 1.1]]), 0.45
    freqs = [2.0**k * np.pi for k in range(cfg.n_freqs_x)]
    h = np.concatenate([x[0]] + [f(c * x[0]) for c in freqs for f in (np.sin, np.cos)] + [[t]])
    layers = params["velocity_mlp"]
    for W, b in layers[:-1]:
        u = h @ W + b
        h = u / (1 + np.exp(-u))
    expected = h @ layers[-1][0] + layers[-1][1]
    np.testing.assert_allclose(mlp_velocity(params, x, t, cfg)[0], expected, rtol=1e-12, atol=1e-14)

