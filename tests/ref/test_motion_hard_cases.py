"""Hard cases of the reference motion model and physics residuals, one named test each:
far extrapolation in time, huge velocities, zero and denormal quaternions, tiny and huge
scales, empty particle sets. Every output and every autograd gradient must be finite (and,
where the answer is known, right). Bad input is pinned per module (tests/ref/motion,
tests/ref/physics: `test_bad_input_names_the_argument`)."""

import math

import autograd.numpy as anp
import numpy as np
import pytest
from autograd import make_vjp
from autograd.misc import flatten
from autograd.tracer import getval

from tests.ref.motion.cases import RIGID_MASK, constant_coefficient_params, random_params, small_cfg
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.motion.deform import adf_residual, compose_state
from velogauss_ref.motion.rotscale import rotscale_rates
from velogauss_ref.motion.trajectory import base_state
from velogauss_ref.motion.velocity import velocity, velocity_field
from velogauss_ref.physics.acceleration import acceleration_field
from velogauss_ref.physics.residuals import divergence, transport_residual
from velogauss_ref.quaternion import quat_multiply

IDENTITY = [1.0, 0.0, 0.0, 0.0]


def finite_with_gradients(fn, args, argnums):
    """fn(*args) as a tuple, after asserting it and its VJP w.r.t. args[argnums] are finite."""
    raw = []

    def flat(*a):
        out = fn(*a)
        out = out if isinstance(out, tuple) else (out,)
        raw.append(tuple(getval(o) for o in out))
        return anp.concatenate([anp.ravel(o) for o in out])

    vjp, y = make_vjp(flat, argnum=argnums)(*args)
    assert np.all(np.isfinite(y)), "output not finite"
    grads, _ = flatten(vjp(np.random.default_rng(0).standard_normal(np.shape(y))))
    assert np.all(np.isfinite(grads)), "gradient not finite"
    return raw[-1]


def _spin_and_translation(omega, b, x0, t):
    """Exact x(t) of x' = omega e_z x x + b: R(a) x0 + (integral_0^t R(omega s) ds) b, a = omega t."""
    a = omega * t
    c, s = math.cos(a), math.sin(a)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    swept = np.array([[s, c - 1.0, 0.0], [1.0 - c, s, 0.0], [0.0, 0.0, a]]) / omega
    return x0 @ R.T + swept @ b, np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)])


def _state(rng, n):
    return rng.uniform(-1, 1, (n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.01, 0.1, (n, 3))


@pytest.mark.spec("VG-COEF", "VG-FIELD", "VG-ADF", "VG-ACC", "VG-TRANSPORT", "VG-DIV")
@pytest.mark.parametrize("t", [-1e3, 1e3])
def test_far_times_everything_finite(t):
    # Random networks a thousand time units away: the time network's pre-activations reach
    # ~1e3, the acceleration polynomial ~1e6, the residuals (grad v) v ~1e6.
    cfg = small_cfg()
    params = random_params(1, cfg)
    x = np.random.default_rng(1).uniform(-1, 1, (3, 3))
    z = physics_code(params, x, cfg)
    finite_with_gradients(lambda p, z, t: coefficients(p, t, z, cfg), (params, z, t), (0, 1, 2))
    finite_with_gradients(lambda p, z, x, t: adf_residual(p, x, t, z, cfg), (params, z, x, t), (0, 1, 2, 3))
    for fn in (velocity_field, acceleration_field, transport_residual, divergence):
        finite_with_gradients(lambda p, x, t: fn(p, x, t, cfg), (params, x, t), (0, 1, 2))


@pytest.mark.spec("VG-TRAJ", "VG-INTEG")
@pytest.mark.parametrize("t", [-1e3, 1e3])
def test_far_time_base_state_follows_the_exact_orbit(t):
    # Spin omega = 0.01 about z plus a translation, a thousand time units forward and
    # backward: 10 rad of turning in 100 RK4 steps of h = 10 (omega h = 0.1).
    omega, b = 0.01, np.array([0.01, -0.005, 0.0002])
    w = np.concatenate([b, [0.0, 0.0, omega], np.zeros(6)])
    cfg = small_cfg(mask=RIGID_MASK)
    params = constant_coefficient_params(0, cfg, w)
    x0, q0, s0 = _state(np.random.default_rng(0), 2)
    x, q, s = base_state(params, x0, q0, s0, physics_code(params, x0, cfg), t, 10.0, "rk4", cfg)
    exact_x, turn = _spin_and_translation(omega, b, x0, t)
    # RK4's phase error ~ (omega h)^5 / 120 per step, 100 steps: 1e-5 rad on orbits of
    # radius ~ |b| / omega + |x0| ~ 2.
    np.testing.assert_allclose(x, exact_x, rtol=0, atol=1e-4)
    np.testing.assert_allclose(s, s0, rtol=1e-13)
    # Same rotation as the positions (q and -q are one rotation).
    expected_q = quat_multiply(turn, q0 / np.linalg.norm(q0, axis=1, keepdims=True))
    np.testing.assert_allclose(np.abs(np.sum(q * expected_q, axis=1)), 1.0, rtol=0, atol=1e-8)


@pytest.mark.spec("VG-TRAJ")
@pytest.mark.parametrize("t", [-1e3, 1e3])
def test_far_time_base_state_gradients_finite(t):
    # Random rigid networks evaluated a thousand time units out (4 RK2 steps of 250): the
    # state is large but finite, and so is every gradient (rigid: s cannot overflow).
    cfg = small_cfg(mask=RIGID_MASK)
    params = random_params(2, cfg)
    x0, q0, s0 = _state(np.random.default_rng(2), 2)
    z = physics_code(params, x0, cfg)
    finite_with_gradients(lambda p, x0, q0, s0, z, t: base_state(p, x0, q0, s0, z, t, 250.0, "rk2", cfg),
                          (params, x0, q0, s0, z, t), (0, 1, 2, 3, 4, 5))


@pytest.mark.spec("VG-TRAJ", "VG-TRANSPORT", "VG-DIV")
def test_huge_velocities_small_step():
    # Coefficients ~1e6: translation ~1e6 and spin 1e6 rad per unit time. h = 1e-7 turns
    # 0.1 rad per step, inside RK4's stability region; t = 1e-5 is 10 rad.
    omega, b = 1e6, np.array([1e6, -2e6, 5e5])
    w = np.concatenate([b, [0.0, 0.0, omega], np.zeros(6)])
    acc = np.zeros((3, 12))
    acc[0, 0:3] = np.cross([0.0, 0.0, omega], b)  # Omega b
    acc[0, 6:9] = [-omega**2, -omega**2, 0.0]  # Omega^2 = diag(-omega^2, -omega^2, 0) for omega along z
    cfg = small_cfg()
    params = constant_coefficient_params(0, cfg, w, acc=acc)
    x0, q0, s0 = _state(np.random.default_rng(0), 3)
    z = physics_code(params, x0, cfg)
    t = 1e-5
    x, q, s = base_state(params, x0, q0, s0, z, t, 1e-7, "rk4", cfg)
    exact_x, _ = _spin_and_translation(omega, b, x0, t)
    # 100 RK4 steps at omega h = 0.1: phase error ~1e-5 rad on orbits of radius ~3.
    np.testing.assert_allclose(x, exact_x, rtol=0, atol=1e-4)
    np.testing.assert_allclose(s, s0, rtol=1e-12)
    # Gradients through the first ten steps (one radian).
    finite_with_gradients(lambda p, x0, q0, s0: base_state(p, x0, q0, s0, z, 1e-6, 1e-7, "rk4", cfg),
                          (params, x0, q0, s0), (0, 1, 2, 3))
    # The residuals of this field: (grad v) v ~ 1e12 is balanced by the centripetal a to
    # rounding (relative 1e-16 on each of a few terms); div v = 0 against |A| ~ 1e6.
    (r,) = finite_with_gradients(lambda p, x: transport_residual(p, x, t, cfg), (params, x0), (0, 1))
    a = acceleration_field(params, x0, t, cfg)
    np.testing.assert_allclose(r, 0.0, rtol=0, atol=1e-13 * np.abs(a).max())
    (div,) = finite_with_gradients(lambda p, x: divergence(p, x, t, cfg), (params, x0), (0, 1))
    np.testing.assert_allclose(div, 0.0, rtol=0, atol=1e-13 * omega)


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE", "VG-ADF-COMPOSE", "VG-QUAT")
def test_zero_and_denormal_quaternions():
    # Zero, denormal and tiny-but-normal (|q|^2 = 4e-26 < QUAT_ZERO_NORM_SQ) quaternions mean
    # "no rotation": identity frame, zero spin rate (q stays below the threshold), finite
    # gradients; a unit quaternion alongside is unaffected.
    q0 = np.array([[0.0, 0.0, 0.0, 0.0], [5e-324, 0.0, 5e-324, 0.0], [1e-13, -1e-13, 0.0, 0.0], IDENTITY])
    cfg = small_cfg()
    params = random_params(0, cfg)
    x0, _, s0 = _state(np.random.default_rng(0), 4)
    z = physics_code(params, x0, cfg)
    x, q, s = finite_with_gradients(lambda p, x0, q0, s0: base_state(p, x0, q0, s0, z, 0.5, 0.1, "rk2", cfg),
                                    (params, x0, q0, s0), (0, 1, 2, 3))
    np.testing.assert_array_equal(q[:3], np.tile(IDENTITY, (3, 1)))
    w = np.random.default_rng(1).standard_normal((4, 12))
    q_dot, log_s_dot = finite_with_gradients(rotscale_rates, (q0, w), (0, 1))
    np.testing.assert_array_equal(q_dot[0], 0.0)
    assert np.all(np.abs(q_dot[:3]) < 1e-12)
    # Identity frame: each axis stretches at the world-axis rate w7, w8, w9.
    np.testing.assert_allclose(log_s_dot, w[:, 6:9], rtol=0, atol=1e-15)
    zeros = np.zeros((4, 3))
    _, q_c, _ = finite_with_gradients(compose_state, (x0, q0, s0, zeros, np.zeros((4, 4)), zeros),
                                     tuple(range(6)))
    np.testing.assert_array_equal(q_c, np.tile(IDENTITY, (4, 1)))


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
@pytest.mark.parametrize("scale", [1e-8, 1e4])
def test_tiny_and_huge_scales(scale):
    # Scales evolve in log space: the relative change is the same at any size.
    cfg = small_cfg()
    params = random_params(0, cfg)
    x0, q0, _ = _state(np.random.default_rng(0), 3)
    z = physics_code(params, x0, cfg)
    _, _, s = finite_with_gradients(lambda p, x0, q0, s0: base_state(p, x0, q0, s0, z, 0.7, 0.1, "rk4", cfg),
                                    (params, x0, q0, np.full((3, 3), scale)), (0, 1, 2, 3))
    _, _, s_unit = base_state(params, x0, q0, np.ones((3, 3)), z, 0.7, 0.1, "rk4", cfg)
    np.testing.assert_allclose(s / scale, s_unit, rtol=1e-12)


@pytest.mark.spec("VG-CODE", "VG-COEF", "VG-VEL", "VG-FIELD", "VG-ROTSCALE", "VG-TRAJ", "VG-ADF", "VG-ADF-COMPOSE",
                  "VG-ACC", "VG-TRANSPORT", "VG-DIV")
def test_no_particles():
    cfg = small_cfg()
    params = random_params(0, cfg)
    x, q, s, w = np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0, 12))
    z = physics_code(params, x, cfg)
    assert z.shape == (0, cfg.code_dim)
    cases = [
        (lambda p, x: physics_code(p, x, cfg), (params, x), [(0, cfg.code_dim)]),
        (lambda p, z: coefficients(p, 0.5, z, cfg), (params, z), [(0, 12)]),
        (velocity, (x, w), [(0, 3)]),
        (lambda p, x: velocity_field(p, x, 0.5, cfg), (params, x), [(0, 3)]),
        (rotscale_rates, (q, w), [(0, 4), (0, 3)]),
        (lambda p, x, q, s: base_state(p, x, q, s + 1.0, z, 0.5, 0.1, "rk2", cfg), (params, x, q, s),
         [(0, 3), (0, 4), (0, 3)]),
        (lambda p, x: adf_residual(p, x, 0.5, z, cfg), (params, x), [(0, 3), (0, 4), (0, 3)]),
        (compose_state, (x, q, s, x, q, s), [(0, 3), (0, 4), (0, 3)]),
        (lambda p, x: acceleration_field(p, x, 0.5, cfg), (params, x), [(0, 3)]),
        (lambda p, x: transport_residual(p, x, 0.5, cfg), (params, x), [(0, 3)]),
        (lambda p, x: divergence(p, x, 0.5, cfg), (params, x), [(0,)]),
    ]
    for fn, args, shapes in cases:
        out = finite_with_gradients(fn, args, tuple(range(len(args))))
        assert [o.shape for o in out] == shapes
