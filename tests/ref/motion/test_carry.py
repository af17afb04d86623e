"""velogauss_ref.motion.carry and base_state's start time: VG-STEP, VG-ADF-STATE, VG-CARRY
(training scheme (b))."""

import numpy as np
import pytest
from autograd import grad

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import FD_STEP, RIGID_MASK, flat_outputs, flat_params, random_params, small_cfg
from velogauss_core.motion import carry_start
from velogauss_ref.motion.carry import adf_state, carried_state
from velogauss_ref.motion.deform import adf_residual
from velogauss_ref.motion.trajectory import base_state, normalize_quat


def _state(rng, n, cfg):
    return (rng.uniform(-1, 1, (n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.05, 0.2, (n, 3)),
            rng.standard_normal((n, cfg.code_dim)))


@pytest.mark.spec("VG-STEP", "VG-TRAJ")
@pytest.mark.parametrize("method", ["euler", "rk2", "rk4"])
def test_two_legs_equal_one_integration(method):
    # 0 -> 0.5 -> 1 with h = 0.125 visits the same stage times as 0 -> 1 in 8 steps, so the
    # chained state equals the direct one up to rounding (the step sizes are exact binary).
    cfg = small_cfg()
    params = random_params(3, cfg)
    x0, q0, s0, z = _state(np.random.default_rng(3), 5, cfg)
    direct = base_state(params, x0, q0, s0, z, 1.0, 0.125, method, cfg)
    half = base_state(params, x0, q0, s0, z, 0.5, 0.125, method, cfg)
    chained = base_state(params, *half, z, 1.0, 0.125, method, cfg, t0=0.5)
    for a, b in zip(direct, chained):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


@pytest.mark.spec("VG-STEP")
def test_start_time_gradient_matches_finite_differences():
    cfg = small_cfg(mask=RIGID_MASK)
    params = random_params(4, cfg)
    theta, unflatten = flat_params(params)
    x0, q0, s0, z = _state(np.random.default_rng(4), 3, cfg)

    def f(theta, x0, q0, s0, t0):
        return base_state(unflatten(theta), x0, q0, s0, z, 0.9, 0.125, "rk2", cfg, t0=t0)

    # t0 = 0.33: 0.57 / 0.125 = 4.56 steps, so the probes t0 +- 1e-4 keep n = 5.
    check_grads_fd(flat_outputs(f), (theta, x0, q0, s0, 0.33), (0, 1, 2, 3, 4), np.random.default_rng(5), step=FD_STEP)


@pytest.mark.spec("VG-ADF-STATE")
def test_adf_state_is_the_canonical_state_moved_by_the_adf():
    cfg = small_cfg()
    params = random_params(6, cfg)
    x0, q0, s0, z = _state(np.random.default_rng(6), 4, cfg)
    dx, dq, ds = adf_residual(params, x0, 0.4, z, cfg)
    x, q, s = adf_state(params, x0, q0, s0, z, 0.4, cfg)
    np.testing.assert_allclose(x, x0 + dx, rtol=1e-15)
    np.testing.assert_allclose(s, s0 * np.exp(ds), rtol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, rtol=1e-14)
    # A zero last layer is the identity deformation.
    W, b = params["adf"][-1]
    params["adf"][-1] = (np.zeros_like(W), np.zeros_like(b))
    x, q, s = adf_state(params, x0, q0, s0, z, 0.4, cfg)
    np.testing.assert_allclose(x, x0, rtol=0, atol=0)
    np.testing.assert_allclose(q, normalize_quat(q0), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-ADF-STATE")
def test_adf_state_gradient_matches_finite_differences():
    cfg = small_cfg()
    theta, unflatten = flat_params(random_params(7, cfg))
    x0, q0, s0, z = _state(np.random.default_rng(7), 3, cfg)

    def f(theta, x0, q0, s0, z, t):
        return adf_state(unflatten(theta), x0, q0, s0, z, t, cfg)

    check_grads_fd(flat_outputs(f), (theta, x0, q0, s0, z, 0.3), (0, 1, 2, 3, 4, 5), np.random.default_rng(8),
                   step=FD_STEP)


@pytest.mark.spec("VG-CARRY")
@pytest.mark.parametrize("t, offset, expected", [
    (0.5, 0.05, 0.45), (0.5, -0.05, 0.55), (0.0, 0.05, 0.0), (0.74, -0.05, 0.75), (0.9, 0.05, 0.75),
    (0.9, 0.0, 0.75), (0.3, 0.0, 0.3)])
def test_carry_start(t, offset, expected):
    assert carry_start(t, offset, 0.75) == pytest.approx(expected, abs=1e-15)


@pytest.mark.spec("VG-CARRY")
def test_carried_values_are_the_velocity_step_from_the_adf_state():
    cfg = small_cfg()
    params = random_params(9, cfg)
    x0, q0, s0, z = _state(np.random.default_rng(9), 4, cfg)
    start = adf_state(params, x0, q0, s0, z, 0.75, cfg)
    want = base_state(params, *start, z, 0.95, 0.05, "rk2", cfg, t0=0.75)
    got = carried_state(params, x0, q0, s0, z, 0.95, 0.75, 0.05, "rk2", cfg)
    for a, b in zip(want, got):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-13)
    # A start at t itself is a step of length 0: the ADF's state.
    same = carried_state(params, x0, q0, s0, z, 0.4, 0.4, 0.05, "rk2", cfg)
    for a, b in zip(adf_state(params, x0, q0, s0, z, 0.4, cfg), same):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-14)


@pytest.mark.spec("VG-CARRY")
def test_gradients_split_between_the_adf_and_the_velocity():
    # d<x, c>/d(ADF weights) is that of the ADF's own x (the step is a fixed displacement for
    # it), and d<x, c>/d(time network) is that of the step from a constant start.
    cfg = small_cfg()
    params = random_params(10, cfg)
    x0, q0, s0, z = _state(np.random.default_rng(10), 4, cfg)
    c = np.random.default_rng(11).standard_normal((4, 3))

    def with_(key, value):
        return {**params, key: value}

    def carried_x(key):
        return lambda v: np.sum(carried_state(with_(key, v), x0, q0, s0, z, 0.5, 0.45, 0.05, "rk2", cfg)[0] * c)

    adf_only = grad(lambda v: np.sum(adf_state(with_("adf", v), x0, q0, s0, z, 0.45, cfg)[0] * c))(params["adf"])
    start = adf_state(params, x0, q0, s0, z, 0.45, cfg)
    step_only = grad(lambda v: np.sum(base_state(with_("time", v), *start, z, 0.5, 0.05, "rk2", cfg, t0=0.45)[0]
                                      * c))(params["time"])
    for got, want in zip(grad(carried_x("adf"))(params["adf"]), adf_only):
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-14)
    for got, want in zip(grad(carried_x("time"))(params["time"]), step_only):
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-12, atol=1e-14)


@pytest.mark.spec("VG-LOSS-CARRY")
def test_carry_loss_is_the_squared_gap_and_trains_only_the_velocity():
    from velogauss_ref.motion.carry import carry_loss

    cfg = small_cfg()
    params = random_params(12, cfg)
    x0, q0, s0, z = _state(np.random.default_rng(12), 5, cfg)
    start = adf_state(params, x0, q0, s0, z, 0.2, cfg)
    xv = base_state(params, *start, z, 0.5, 0.05, "rk2", cfg, t0=0.2)[0]
    gap = xv - adf_state(params, x0, q0, s0, z, 0.5, cfg)[0]
    assert carry_loss(params, x0, q0, s0, z, 0.2, 0.5, 0.05, "rk2", cfg) == pytest.approx(np.mean(np.sum(gap**2, 1)),
                                                                                           rel=1e-14)
    # The ADF's states are constants: no gradient reaches the ADF weights.
    g = grad(lambda adf: carry_loss({**params, "adf": adf}, x0, q0, s0, z, 0.2, 0.5, 0.05, "rk2", cfg))(params["adf"])
    assert all(np.all(W == 0) and np.all(b == 0) for W, b in g)
    # The velocity's do, and the gradient w.r.t. the time network matches finite differences.
    theta, unflatten = flat_params(params["time"])

    def f(theta):
        return carry_loss({**params, "time": unflatten(theta)}, x0, q0, s0, z, 0.2, 0.5, 0.05, "rk2", cfg)

    check_grads_fd(f, (theta,), (0,), np.random.default_rng(13), step=FD_STEP)
