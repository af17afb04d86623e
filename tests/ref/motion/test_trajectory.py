"""velogauss_ref.motion.trajectory: VG-TRAJ, the base state (x, q, s) integrated from t = 0,
against closed-form motions and the invariants of rigid motion (VG-ROTSCALE along a path)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, TRANSLATION_MASK, constant_coefficient_params, flat_outputs,
                                    flat_params, random_params, small_cfg)
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.motion.trajectory import base_state
from velogauss_ref.motion.velocity import velocity
from velogauss_ref.quaternion import quat_multiply, quat_to_rotmat

seeds = st.integers(0, 2**32 - 1)


def _state(rng, n, cfg):
    return (rng.uniform(-1, 1, (n, 3)), rng.standard_normal((n, 4)), rng.uniform(0.01, 0.2, (n, 3)),
            rng.standard_normal((n, cfg.code_dim)))


def _unit(q):
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _rot_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.spec("VG-TRAJ")
def test_t_zero_returns_the_canonical_state():
    cfg = small_cfg()
    x0, q0, s0, z = _state(np.random.default_rng(1), 5, cfg)
    x, q, s = base_state(random_params(1, cfg), x0, q0, s0, z, 0.0, 0.1, "rk4", cfg)
    np.testing.assert_array_equal(x, x0)
    np.testing.assert_allclose(s, s0, rtol=1e-15, atol=0)  # exp(log s0): one rounding each way
    np.testing.assert_allclose(q, _unit(q0), rtol=0, atol=1e-15)


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
@pytest.mark.parametrize("t", [0.9, -0.9])
def test_constant_spin_is_a_rigid_rotation(t):
    # x(t) = Rz(omega t) x0, q(t) = rot(omega t) (x) q0, s = s0, forward and backward in time.
    omega = 1.3
    w = np.zeros(12)
    w[5] = omega
    cfg = small_cfg()
    x0, q0, s0, z = _state(np.random.default_rng(2), 6, cfg)
    x, q, s = base_state(constant_coefficient_params(2, cfg, w), x0, q0, s0, z, t, 0.01, "rk4", cfg)
    a = omega * t
    # RK4 at h = 0.01: global error ~ (h omega)^4 t ~ 3e-9 on O(1) values.
    np.testing.assert_allclose(x, x0 @ _rot_z(a).T, rtol=0, atol=1e-7)
    np.testing.assert_allclose(s, s0, rtol=1e-12, atol=0)
    turn = np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)])
    np.testing.assert_allclose(quat_to_rotmat(q), quat_to_rotmat(quat_multiply(turn, q0)), rtol=0, atol=1e-7)


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
@pytest.mark.parametrize("method", ["euler", "rk2", "rk4"])
def test_translation_and_axis_stretch(method):
    # Constant translation b and stretch rates k with an identity frame: log s has a constant
    # rate, so every method gives s = s0 exp(k t) exactly; x_i = (x0_i + b_i / k_i) e^(k_i t) - b_i / k_i
    # (x0_i + b_i t where k_i = 0).
    w = np.zeros(12)
    w[0:3] = [0.5, -1.0, 0.25]
    w[6:9] = [0.4, -0.3, 0.0]
    cfg = small_cfg()
    x0, _, s0, z = _state(np.random.default_rng(4), 5, cfg)
    q0 = np.tile([1.0, 0.0, 0.0, 0.0], (5, 1))
    t = -0.8
    x, q, s = base_state(constant_coefficient_params(4, cfg, w), x0, q0, s0, z, t, 0.02, method, cfg)
    k, b = w[6:9], w[0:3]
    np.testing.assert_allclose(s, s0 * np.exp(k * t), rtol=1e-12, atol=0)
    np.testing.assert_allclose(q, q0, rtol=0, atol=1e-15)
    safe_k = np.where(k == 0, 1.0, k)
    exact = np.where(k == 0, x0 + b * t, (x0 + b / safe_k) * np.exp(k * t) - b / safe_k)
    # Euler's global error at h = 0.02 is ~ h k^2 |t| |x| / 2 ~ 2e-3, RK2's ~ h^2 (measured
    # 8e-6), RK4's ~ h^4 (measured 2e-11): each bound leaves about 3x headroom.
    np.testing.assert_allclose(x, exact, rtol=0, atol={"euler": 1e-2, "rk2": 3e-5, "rk4": 1e-10}[method])


@pytest.mark.spec("VG-TRAJ", "VG-ROTSCALE")
@settings(max_examples=5)
@given(seeds, st.sampled_from([0.7, -0.5]))
def test_rigid_body_moves_rigidly(seed, t):
    # A body (particles sharing one code) under a time-varying rigid-only field (translation
    # and rotation columns): pairwise distances and scales are preserved, and every
    # particle's frame R(q) turns by the same rotation as the body's positions.
    cfg = small_cfg(mask=RIGID_MASK)
    rng = np.random.default_rng(seed)
    x0, q0, s0, _ = _state(rng, 5, cfg)
    z = np.tile(rng.standard_normal(cfg.code_dim), (5, 1))
    x, q, s = base_state(random_params(seed, cfg), x0, q0, s0, z, t, 0.02, "rk4", cfg)
    # RK4 at h = 0.02 with rates |w| < 1 on these parameters: measured errors below 3e-11
    # (distances, R_body and the frames alike); 1e-9 leaves 30x headroom and still fails a
    # frame that turns differently from the body at the 1e-3 level.
    distances = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(distances(x), distances(x0), rtol=0, atol=1e-9)
    # A rigid field has no strain (D = 0 exactly), so log s is constant: s = exp(log s0).
    np.testing.assert_allclose(s, s0, rtol=1e-15, atol=0)
    # The body's rotation maps the canonical displacements x0_i - x0_0 onto the current ones.
    D0, D1 = (x0[1:4] - x0[0]).T, (x[1:4] - x[0]).T
    R_body = D1 @ np.linalg.inv(D0)
    np.testing.assert_allclose(R_body @ R_body.T, np.eye(3), rtol=0, atol=1e-9)
    np.testing.assert_allclose(quat_to_rotmat(q), R_body @ quat_to_rotmat(q0), rtol=0, atol=1e-9)


@pytest.mark.spec("VG-TRAJ")
@settings(max_examples=6)
@given(seed=seeds, method=st.sampled_from(["euler", "rk2", "rk4"]), t=st.sampled_from([0.55, -0.3, 0.0]),
       masked=st.booleans())
def test_base_state_gradient(seed, method, t, masked):
    # |t| / h = 2.2, 1.2 or 0: finite differences in t never cross a change of the step
    # count ceil(|t| / h) (t = 0 is one step of size t on either side, smooth).
    cfg = small_cfg(mask=RIGID_MASK if masked else None)
    theta, unflatten = flat_params(random_params(seed, cfg))
    x0, q0, s0, z = _state(np.random.default_rng(seed), 2, cfg)
    q0 = q0 / np.linalg.norm(q0, axis=1, keepdims=True)  # |q|^2 = 1, far from QUAT_ZERO_NORM_SQ

    def f(theta, x0, q0, s0, z, t):
        return base_state(unflatten(theta), x0, q0, s0, z, t, 0.25, method, cfg)

    check_grads_fd(flat_outputs(f), (theta, x0, q0, s0, z, t), (0, 1, 2, 3, 4, 5), np.random.default_rng(seed),
                   step=FD_STEP)


@pytest.mark.parametrize(
    "change, name",
    [
        (dict(s0=-np.ones((3, 3))), "s0"),
        (dict(s0=np.zeros((3, 3))), "s0"),
        (dict(q0=np.ones((2, 4))), "q0"),
        (dict(x0=np.full((3, 3), np.nan)), "x0"),
        (dict(z=np.zeros((3, 2))), "z"),
        (dict(h=0.0), "h"),
        (dict(h=-0.5), "h"),
        (dict(t=np.nan), "t"),
        (dict(method="midpoint"), "method"),
    ],
)
def test_bad_input_names_the_argument(change, name):
    cfg = small_cfg()
    x0, q0, s0, z = _state(np.random.default_rng(0), 3, cfg)
    args = {**dict(x0=x0, q0=q0, s0=s0, z=z, t=0.5, h=0.1, method="rk2"), **change}
    with pytest.raises(ValueError, match=f"^{name}:"):
        base_state(random_params(0, cfg), cfg=cfg, **args)


@pytest.mark.spec("VG-COEF-COAST")
@given(seed=seeds, t=st.floats(0.3, 2.0), method=st.sampled_from(["euler", "rk2"]))
def test_coasting_integrates_on_in_the_field_of_the_window_s_last_patterns(seed, t, method):
    # Translation only: the field is uniform in x, so each step adds dt times the velocity at
    # its stage time (Euler: the step's start; midpoint RK2: its middle), read at
    # min(stage time, T) through VG-COEF's coefficients and VG-VEL; T = 0.6.
    T, h = 0.6, 0.05
    coast = small_cfg(mask=TRANSLATION_MASK, max_time=T, future="coast")
    window = small_cfg(mask=TRANSLATION_MASK, max_time=T)
    rng = np.random.default_rng(seed)
    params = random_params(seed, coast)
    x0, z = rng.standard_normal((5, 3)), rng.standard_normal((5, coast.code_dim))
    q0, s0 = rng.standard_normal((5, 4)), rng.uniform(0.5, 2.0, (5, 3))
    n = math.ceil(t / h)
    dt = t / n
    stage = {"euler": 0.0, "rk2": 0.5}[method]
    expected = x0 + sum(dt * velocity(x0, coefficients(params, min(k * dt + stage * dt, T), z, window))
                        for k in range(n))
    x, _, _ = base_state(params, x0, q0, s0, z, t, h, method, coast)
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-12)
