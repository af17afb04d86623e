"""Explicit Euler, midpoint RK2 and classic RK4 integration, in torch.

Twin of `velogauss_ref.motion.integrate` (spec/motion.md, VG-INTEG). The state is one
tensor for all particles; only the time steps are a Python loop.
"""

import math
from typing import NamedTuple

import torch

from velogauss_core.motion import INTEGRATORS, Integrator
from velogauss_fast.motion.scalars import check_time


def integrate(f, y0: torch.Tensor, t0, t1, h, method: Integrator) -> torch.Tensor:
    """y(t1) from y(t0) = y0 and dy/dt = f(y, t) with fixed steps (VG-INTEG).

    f: callable (y (..., D), t) -> (..., D); y0: (..., D) tensor; t0, t1: scalar times
    (numbers or 0-d tensors; t1 < t0 integrates backward); h > 0: maximum step size;
    method: "euler" | "rk2" (midpoint) | "rk4" (classic).
    Takes n = max(1, ceil(|t1 - t0| / h)) steps of (t1 - t0) / n, so the last lands exactly
    on t1. t1 == t0 is one step of size 0: it returns y0, and its gradients with respect to
    t0 and t1 are the exact ones (-f(y0, t0) and f(y0, t0)). The times passed to f are
    t0 + k dt (+ stage offsets), and carry t0's and t1's autograd graph when they are tensors.
    Raises ValueError for h <= 0, a non-finite time or h, or an unknown method.
    """
    return integrate_schedule(f, y0, schedule(t0, t1, h, method))


def integrate_schedule(f, y0: torch.Tensor, sched: "Schedule") -> torch.Tensor:
    """`integrate` along a schedule computed once by `schedule` (shared with `Schedule.stage_times`)."""
    if not isinstance(y0, torch.Tensor):
        raise ValueError(f"y0: expected a torch.Tensor, got {type(y0).__name__}")
    step = _STEPS[sched.method]
    y = y0
    for k in range(sched.n):
        y = step(f, y, sched.t0 + k * sched.dt, sched.dt)
    return y


def stage_times(t0, t1, h, method: Integrator) -> list:
    """The times at which `integrate(f, y0, t0, t1, h, method)` calls f, in call order (VG-INTEG).

    A list of n * stages entries (1, 2 or 4 stages per step), each computed exactly as
    `integrate` computes it (numbers, or 0-d tensors carrying t0's and t1's graph), so a
    caller can evaluate what f needs at every stage at once, before integrating.
    Raises ValueError as `integrate` does.
    """
    return schedule(t0, t1, h, method).stage_times()


class Schedule(NamedTuple):
    """The fixed steps of one integration: n steps of dt from t0 with `method` (VG-INTEG)."""

    t0: object  # number or 0-d tensor
    n: int
    dt: object  # (t1 - t0) / n: number or 0-d tensor
    method: Integrator

    def stage_times(self) -> list:
        """The times at which the integration calls f, in call order (see `stage_times`)."""
        return [tau for k in range(self.n) for tau in _STAGE_TIMES[self.method](self.t0 + k * self.dt, self.dt)]


def schedule(t0, t1, h, method: Integrator) -> Schedule:
    """n = max(1, ceil(|t1 - t0| / h)) steps of dt = (t1 - t0) / n from t0, after validating
    t0, t1, h and method (ValueError naming the argument)."""
    check_time("t0", t0)
    check_time("t1", t1)
    check_time("h", h)
    if float(h) <= 0:
        raise ValueError(f"h: expected a positive step size, got {float(h)!r}")
    if method not in INTEGRATORS:
        raise ValueError(f"method: expected one of {INTEGRATORS}, got {method!r}")
    n = max(1, math.ceil(abs(float(t1) - float(t0)) / float(h)))
    return Schedule(t0, n, (t1 - t0) / n, method)


def _euler(f, y, t, dt):
    return _axpy(y, dt, f(y, t))


def _rk2(f, y, t, dt):
    k1 = f(y, t)
    return _axpy(y, dt, f(_axpy(y, 0.5 * dt, k1), t + 0.5 * dt))


def _rk4(f, y, t, dt):
    k1 = f(y, t)
    k2 = f(_axpy(y, 0.5 * dt, k1), t + 0.5 * dt)
    k3 = f(_axpy(y, 0.5 * dt, k2), t + 0.5 * dt)
    k4 = f(_axpy(y, dt, k3), t + dt)
    return _axpy(y, dt / 6, k1 + 2 * k2 + 2 * k3 + k4)


def _axpy(y, a, k):
    """y + a k: one tensor op (and one autograd node) when the step a is a number, where
    y + a * k takes two; a tensor step (t0 or t1 requiring grad) keeps its graph."""
    if isinstance(a, torch.Tensor):
        return y + a * k
    return torch.add(y, k, alpha=a)


_STEPS = {"euler": _euler, "rk2": _rk2, "rk4": _rk4}
# The stage times of one step from t, as the step functions above compute them.
_STAGE_TIMES = {
    "euler": lambda t, dt: (t,),
    "rk2": lambda t, dt: (t, t + 0.5 * dt),
    "rk4": lambda t, dt: (t, t + 0.5 * dt, t + 0.5 * dt, t + dt),
}
