"""velogauss_ref.motion.integrate: VG-INTEG (Euler, midpoint RK2, classic RK4), forward and
backward in time, against exact solutions."""

import autograd.numpy as anp
import numpy as np
import pytest
from autograd import make_vjp
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from velogauss_ref.motion.integrate import integrate

METHODS = ["euler", "rk2", "rk4"]
ORDER = {"euler": 1, "rk2": 2, "rk4": 4}
# Stages per step, and where the last stage sits within its step (fraction of dt).
STAGES = {"euler": 1, "rk2": 2, "rk4": 4}
LAST_STAGE = {"euler": 0.0, "rk2": 0.5, "rk4": 1.0}

seeds = st.integers(0, 2**32 - 1)


def spin(y, t):
    """A rigid rotation about z at the accelerating rate 1 + t: y' = omega(t) e_z x y."""
    rate = 1.0 + t
    return anp.stack([-rate * y[..., 1], rate * y[..., 0], 0.0 * y[..., 2]], axis=-1)


def spin_exact(y0, t0, t1):
    """The exact solution of `spin`: a turn by theta = (t1 + t1^2 / 2) - (t0 + t0^2 / 2) on a circle."""
    theta = (t1 + 0.5 * t1 * t1) - (t0 + 0.5 * t0 * t0)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * y0[..., 0] - s * y0[..., 1], s * y0[..., 0] + c * y0[..., 1], y0[..., 2]], axis=-1)


def rhs(y, t):
    """A non-linear, non-autonomous right-hand side for the gradient checks."""
    return -0.7 * y + 0.5 * t * y * y / (1 + y * y)


Y0 = np.array([[1.0, 0.0, 0.5], [0.3, -0.8, -1.0]])


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("t0, t1", [(0.0, 1.5), (0.5, -1.0)])
def test_convergence_order_on_a_rigid_rotation(method, t0, t1):
    exact = spin_exact(Y0, t0, t1)
    errors = [np.abs(integrate(spin, Y0, t0, t1, h, method) - exact).max() for h in (0.02, 0.01)]
    ratio = errors[0] / errors[1]
    # Halving h divides the global error by 2^order, up to the next-order term: at h ~ 0.01
    # with rates ~2 that term shifts the ratio by ~10%; RK4's errors (~1e-9) stay far
    # above rounding (~1e-15).
    assert 0.8 * 2 ** ORDER[method] < ratio < 1.25 * 2 ** ORDER[method], (errors, ratio)


@pytest.mark.spec("VG-INTEG")
def test_rk4_stays_on_the_circle():
    # RK4 at h = 0.01 and rates <= 2.5: global error ~ (h rate)^4 t ~ 1e-8 on the exact circle.
    y1 = integrate(spin, Y0, 0.0, 1.5, 0.01, "rk4")
    np.testing.assert_allclose(y1, spin_exact(Y0, 0.0, 1.5), rtol=0, atol=1e-8)
    np.testing.assert_allclose(np.linalg.norm(y1[:, :2], axis=1), np.linalg.norm(Y0[:, :2], axis=1), atol=1e-8)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
def test_backward_integration_inverts_forward(method):
    # Forward 0 -> 1.2, then back 1.2 -> 0 from where it landed: the round trip returns to
    # y0 up to the method's truncation error, which falls at least as fast as its order
    # (Euler O(h); midpoint RK2 O(h^3), as its round trip cancels a term; RK4 O(h^5)).
    errors = []
    for h in (0.02, 0.01):
        y1 = integrate(spin, Y0, 0.0, 1.2, h, method)
        errors.append(np.abs(integrate(spin, y1, 1.2, 0.0, h, method) - Y0).max())
    # Measured at h = 0.01: 3e-2 (Euler), 3e-6 (RK2), 6e-11 (RK4).
    assert errors[1] < {"euler": 0.05, "rk2": 1e-5, "rk4": 1e-9}[method], errors
    assert errors[0] / errors[1] > 0.8 * 2 ** ORDER[method], errors


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("t0, t1, h, n", [(0.0, 1.0, 0.3, 4), (1.0, -1.0, 0.5, 4), (0.0, 0.01, 1.0, 1),
                                          (2.0, 2.0, 0.1, 1)])
def test_step_count_and_landing(method, t0, t1, h, n):
    calls = []

    def one(y, t):
        calls.append(float(t))
        return np.ones_like(y)

    y1 = integrate(one, np.zeros(2), t0, t1, h, method)
    # Every method integrates a constant rate exactly, whatever the sign of t1 - t0.
    np.testing.assert_allclose(y1, np.full(2, t1 - t0), rtol=0, atol=1e-15)
    # n = max(1, ceil(|t1 - t0| / h)) steps of (t1 - t0) / n: t1 = t0 is one step of size 0.
    assert len(calls) == STAGES[method] * n
    dt = (t1 - t0) / n
    assert calls[0] == t0
    assert calls[-1] == pytest.approx(t0 + (n - 1) * dt + LAST_STAGE[method] * dt)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
def test_zero_span_returns_y0_with_the_exact_time_derivatives(method):
    vjp, y1 = make_vjp(lambda t0, t1: integrate(spin, Y0, t0, t1, 0.1, method), argnum=(0, 1))(0.4, 0.4)
    np.testing.assert_array_equal(y1, Y0)
    w = np.random.default_rng(0).standard_normal(Y0.shape)
    d_t0, d_t1 = vjp(w)
    # y(t1; t0, y0) has dy/dt1 = f(y0, t0) and dy/dt0 = -f(y0, t0) at t1 = t0.
    expected = np.sum(w * spin(Y0, 0.4))
    np.testing.assert_allclose([d_t0, d_t1], [-expected, expected], rtol=1e-14)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
@given(y0=hnp.arrays(np.float64, (2, 3), elements=st.floats(-2, 2)),
       span=st.sampled_from([(0.0, 1.0), (0.0, -0.8), (0.3, 0.3), (-1.0, 2.45)]),
       h=st.sampled_from([0.07, 0.3, 5.0]), seed=seeds)
def test_integrate_gradient(method, y0, span, h, seed):
    # The step count ceil(|t1 - t0| / h) jumps where |t1 - t0| / h is an integer; none of
    # these spans is within the finite-difference probe (1e-6) of one, and t1 = t0 is
    # smooth (one step of size t1 - t0 on either side).
    t0, t1 = span
    check_grads_fd(lambda y0, t0, t1: integrate(rhs, y0, t0, t1, h, method), (y0, t0, t1), (0, 1, 2),
                   np.random.default_rng(seed))


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(h=0.0), "h"),
        (dict(h=-0.1), "h"),
        (dict(h=np.nan), "h"),
        (dict(t1=np.inf), "t1"),
        (dict(t0=np.nan), "t0"),
        (dict(t0=np.zeros(2)), "t0"),
        (dict(method="rk3"), "method"),
        (dict(method="midpoint"), "method"),
        (dict(y0=np.array([0.0, np.nan])), "y0"),
    ],
)
def test_bad_input_names_the_argument(kwargs, name):
    args = {"f": rhs, "y0": np.zeros(2), "t0": 0.0, "t1": 1.0, "h": 0.1, "method": "rk2", **kwargs}
    with pytest.raises(ValueError, match=f"^{name}:"):
        integrate(**args)
