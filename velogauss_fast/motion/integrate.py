"""Explicit Euler, midpoint RK2 and classic RK4 integration, in torch.

Twin of `velogauss_ref.motion.integrate` (spec/motion.md, VG-INTEG). The state is one
tensor for all particles; only the time steps are a Python loop.
"""

import math

import torch

from velogauss_fast.motion.scalars import check_time

METHODS = ("euler", "rk2", "rk4")


def integrate(f, y0, t0, t1, h, method):
    """y(t1) from y(t0) = y0 and dy/dt = f(y, t) with fixed steps (VG-INTEG).

    f: callable (y (..., D), t) -> (..., D); y0: (..., D) tensor; t0, t1: scalar times
    (numbers or 0-d tensors; t1 < t0 integrates backward); h > 0: maximum step size;
    method: "euler" | "rk2" (midpoint) | "rk4" (classic).
    Takes n = max(1, ceil(|t1 - t0| / h)) steps of (t1 - t0) / n, so the last lands exactly
    on t1; t1 == t0 returns y0. The times passed to f are t0 + k dt (+ stage offsets), and
    carry t0's and t1's autograd graph when they are tensors.
    Raises ValueError for h <= 0, a non-finite time or h, or an unknown method.
    """
    check_time("t0", t0)
    check_time("t1", t1)
    check_time("h", h)
    if float(h) <= 0:
        raise ValueError(f"h: expected a positive step size, got {float(h)!r}")
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    if not isinstance(y0, torch.Tensor):
        raise ValueError(f"y0: expected a torch.Tensor, got {type(y0).__name__}")
    span = float(t1) - float(t0)
    if span == 0:
        return y0
    n = max(1, math.ceil(abs(span) / float(h)))
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
