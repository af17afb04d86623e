"""velogauss_fast.motion.integrate: VG-INTEG (Euler, midpoint RK2, classic RK4) against
velogauss_ref and against exact solutions."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from velogauss_fast.motion.integrate import integrate, stage_times
from velogauss_ref.motion import integrate as ref

METHODS = ["euler", "rk2", "rk4"]


def f(y, t):
    """A non-linear, non-autonomous right-hand side written with operators only, so the same
    function runs on NumPy arrays, autograd boxes and tensors (t a number or a 0-d tensor)."""
    return -0.7 * y + 0.5 * t * y * y / (1 + y * y)


@pytest.mark.spec("VG-INTEG")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), method=st.sampled_from(METHODS),
       span=st.sampled_from([(0.0, 1.0), (0.0, -0.8), (0.3, 0.3), (-1.0, 2.5)]), h=st.sampled_from([0.07, 0.3, 5.0]))
def test_reference_vs_fast(device, seed, method, span, h):
    y0 = np.random.default_rng(seed).standard_normal((4, 3))
    t0, t1 = span
    args = (f, y0, t0, t1, h, method)
    # Differentiated w.r.t. y0 and both end times (the step count is fixed by their values).
    check_agreement(ref.integrate, integrate, args, diff=(1, 2, 3), device=device, seed=seed)
    check_float32(ref.integrate, integrate, args, device)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method, order", [("euler", 1), ("rk2", 2), ("rk4", 4)])
def test_convergence_order(method, order):
    # y' = cos(t) y has y(t1) = y0 exp(sin t1 - sin t0); the time dependence checks the
    # stage times as well as the stage weights.
    def g(y, t):
        return math.cos(t) * y

    y0 = torch.tensor([1.0, -2.0], dtype=torch.float64)
    t0, t1 = 0.2, 1.7
    exact = y0 * math.exp(math.sin(t1) - math.sin(t0))
    errors = [float((integrate(g, y0, t0, t1, h, method) - exact).abs().max()) for h in (0.05, 0.025)]
    ratio = errors[0] / errors[1]
    # Halving h divides the error by 2^order, up to the next-order term at these step sizes.
    assert 0.8 * 2**order < ratio < 1.25 * 2**order, (errors, ratio)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("t0, t1, h, n", [(0.0, 1.0, 0.3, 4), (1.0, -1.0, 0.5, 4), (0.0, 0.01, 1.0, 1), (2.0, 2.0, 0.1, 1)])
def test_step_count_and_landing(method, t0, t1, h, n):
    calls = []

    def one(y, t):
        calls.append(float(t))
        return torch.ones_like(y)

    y0 = torch.zeros(2, dtype=torch.float64)
    y1 = integrate(one, y0, t0, t1, h, method)
    # Every method integrates a constant rate exactly; the n steps land on t1.
    torch.testing.assert_close(y1, torch.full_like(y0, t1 - t0), rtol=0, atol=1e-15)
    stages = {"euler": 1, "rk2": 2, "rk4": 4}[method]
    # t1 == t0 is one step of size 0 (n = max(1, ...)), which keeps d y1 / d t1 = f(y0, t0) exact.
    assert len(calls) == stages * n
    # Steps of (t1 - t0) / n from t0; the last stage sits at offset 0, 1/2, 1 of the last step.
    dt = (t1 - t0) / n
    assert calls[0] == t0
    assert calls[-1] == pytest.approx(t0 + (n - 1) * dt + {"euler": 0.0, "rk2": 0.5, "rk4": 1.0}[method] * dt)


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("t0, t1, h", [(0.0, 0.5, 0.05), (0.0, -0.77, 0.1), (0.25, 0.25, 0.1), (-1.0, 2.5, 0.3)])
@pytest.mark.parametrize("tensor_times", [False, True])
def test_stage_times_are_the_times_f_sees(method, t0, t1, h, tensor_times):
    # base_state evaluates the coefficients of every stage before integrating and hands
    # them out in call order: stage_times must be exactly the times integrate passes to f.
    if tensor_times:
        t0, t1 = torch.tensor(t0, dtype=torch.float64), torch.tensor(t1, dtype=torch.float64, requires_grad=True)
    calls = []

    def record(y, t):
        calls.append(t)
        return y

    integrate(record, torch.zeros(1, dtype=torch.float64), t0, t1, h, method)
    times = stage_times(t0, t1, h, method)
    assert len(times) == len(calls)
    assert all(type(a) is type(b) and float(a) == float(b) for a, b in zip(times, calls))


@pytest.mark.spec("VG-INTEG")
@pytest.mark.parametrize("method", METHODS)
def test_gradcheck(device, method):
    y0 = np.random.default_rng(0).standard_normal((2, 3))
    gradcheck_fn(integrate, (f, y0, 0.1, 0.9, 0.25, method), diff=(1, 2, 3), device=device)


@pytest.mark.spec("VG-INTEG")
def test_rejects_bad_input():
    y0 = torch.zeros(3)
    with pytest.raises(ValueError, match="^h"):
        integrate(f, y0, 0.0, 1.0, 0.0, "rk2")
    with pytest.raises(ValueError, match="^h"):
        integrate(f, y0, 0.0, 1.0, -0.1, "rk2")
    with pytest.raises(ValueError, match="^t1"):
        integrate(f, y0, 0.0, float("inf"), 0.1, "rk2")
    with pytest.raises(ValueError, match="^t0"):
        integrate(f, y0, float("nan"), 1.0, 0.1, "rk2")
    with pytest.raises(ValueError, match="^method"):
        integrate(f, y0, 0.0, 1.0, 0.1, "rk3")
    with pytest.raises(ValueError, match="^h"):
        stage_times(0.0, 1.0, 0.0, "rk2")
    with pytest.raises(ValueError, match="^method"):
        stage_times(0.0, 1.0, 0.1, "rk3")
