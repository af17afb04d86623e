"""Explicit fixed-step integration: Euler, midpoint RK2 and classic RK4.

spec/motion.md, VG-INTEG.
"""

import math

from autograd.tracer import getval

from velogauss_core.motion import INTEGRATORS
from velogauss_ref.checks import check_array, check_scalar


def integrate(f, y0, t0, t1, h, method):
    """y(t1) for dy/dt = f(y, t), y(t0) = y0, by n equal explicit steps (VG-INTEG).

    f: callable (y (..., D), t) -> dy/dt (..., D); y0: (..., D); t0, t1: scalar times
    (t1 < t0 integrates backward); h > 0: the largest step allowed; method: "euler",
    "rk2" (midpoint) or "rk4" (classic).
    Takes n = max(1, ceil(|t1 - t0| / h)) steps of signed size (t1 - t0) / n, so the last
    one lands exactly on t1. t1 = t0 is one step of size 0: it returns y0, and its
    derivatives with respect to t0 and t1 are the exact ones (-f(y0, t0) and f(y0, t0)).
    Raises ValueError for h <= 0, a non-finite time, h or y0, or an unknown method.
    """
    check_scalar("t0", t0)
    check_scalar("t1", t1)
    check_scalar("h", h)
    if not getval(h) > 0:
        raise ValueError(f"h: expected a positive step size, got {getval(h)!r}")
    if method not in INTEGRATORS:
        raise ValueError(f"method: expected one of {INTEGRATORS}, got {method!r}")
    check_array("y0", y0)
    # The step count is piecewise constant in t0 and t1: it carries no derivative.
    n = max(1, math.ceil(abs(float(getval(t1)) - float(getval(t0))) / float(getval(h))))
    dt = (t1 - t0) / n
    step = _STEPS[method]
    y = y0
    for k in range(n):
        y = step(f, y, t0 + k * dt, dt)
    return y


def _euler(f, y, t, dt):
    return y + dt * f(y, t)


def _rk2(f, y, t, dt):
    k1 = f(y, t)
    return y + dt * f(y + (0.5 * dt) * k1, t + 0.5 * dt)


def _rk4(f, y, t, dt):
    k1 = f(y, t)
    k2 = f(y + (0.5 * dt) * k1, t + 0.5 * dt)
    k3 = f(y + (0.5 * dt) * k2, t + 0.5 * dt)
    k4 = f(y + dt * k3, t + dt)
    return y + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)


_STEPS = {"euler": _euler, "rk2": _rk2, "rk4": _rk4}
