"""Analytic affine motions of the synthetic scenes' bodies.

A motion maps a material point's canonical position `x0` (its world position at `t = 0`)
to its world position at time `t`: `x(t) = A(t) x0 + b(t)`, with `A(0) = I`, `b(0) = 0`.
Because the map is affine, the Eulerian velocity and acceleration of the body are affine
fields of the world point `x`:

    v(x, t) = G(t) x + g(t),   G = Ȧ A⁻¹,  g = ḃ − G b
    a(x, t) = Ä A⁻¹ (x − b) + b̈        (material acceleration Dv/Dt)

so every body's motion is exactly one point of the paper's 12-dimensional affine basis
(VG-BASIS) at each time: see `basis_coefficients`.
"""

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from velogauss_core.checks import check_array, check_scalar


def _vec(name, value):
    return np.array(check_array(name, np.asarray(value, dtype=np.float64), (3,)), dtype=np.float64)


def _cross_matrix(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


class Motion:
    """Base class: subclasses define `affine`, `rate`, `second_rate` and `to_dict`."""

    def affine(self, t):
        """`(A (3, 3), b (3,))` with `x(t) = A x0 + b`."""
        raise NotImplementedError

    def rate(self, t):
        """First time derivatives `(Ȧ, ḃ)` of `affine(t)`."""
        raise NotImplementedError

    def second_rate(self, t):
        """Second time derivatives `(Ä, b̈)` of `affine(t)`."""
        raise NotImplementedError

    def to_dict(self):
        """A JSON-serialisable description that `motion_from_dict` turns back into this motion."""
        raise NotImplementedError

    def matrix(self, t):
        """The homogeneous map `M(t)` (4, 4) = `[[A, b], [0, 0, 0, 1]]` from canonical to world."""
        A, b = self.affine(check_scalar("t", t))
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = A, b
        return M

    def position(self, x0, t):
        """World positions `(N, 3)` at time `t` of the material points at `x0 (N, 3)` at `t = 0`."""
        A, b = self.affine(check_scalar("t", t))
        return np.asarray(check_array("x0", x0, (None, 3)), dtype=np.float64) @ A.T + b

    def canonical(self, x, t):
        """Inverse of `position`: canonical positions `(N, 3)` of the points at `x (N, 3)` at time `t`."""
        A, b = self.affine(check_scalar("t", t))
        return np.linalg.solve(A, (np.asarray(check_array("x", x, (None, 3)), dtype=np.float64) - b).T).T

    def velocity_affine(self, t):
        """`(G (3, 3), g (3,))` with the Eulerian velocity `v(x, t) = G x + g`."""
        A, b = self.affine(check_scalar("t", t))
        A_dot, b_dot = self.rate(t)
        G = np.linalg.solve(A.T, A_dot.T).T
        return G, b_dot - G @ b

    def velocity(self, x, t):
        """Eulerian velocity `(N, 3)` at world points `x (N, 3)` and time `t` (world units per unit time)."""
        G, g = self.velocity_affine(t)
        return np.asarray(check_array("x", x, (None, 3)), dtype=np.float64) @ G.T + g

    def acceleration(self, x, t):
        """Material acceleration `Dv/Dt (N, 3)` at world points `x (N, 3)` and time `t`."""
        A_ddot, b_ddot = self.second_rate(check_scalar("t", t))
        return self.canonical(x, t) @ A_ddot.T + b_ddot

    def basis_coefficients(self, t):
        """The VG-BASIS coefficients `w (12,)` with `Φ(x) w = v(x, t)` for every x.

        Inverts spec/motion.md's `A(w)`: `w1..3 = g`, `(w4, w5, w6)` = axial vector of the
        antisymmetric part of G, `w7..9 = diag G`, `(w10, w11, w12)` = the (xy, yz, xz)
        entries of its symmetric part.
        """
        G, g = self.velocity_affine(t)
        spin = 0.5 * (G - G.T)
        strain = 0.5 * (G + G.T)
        return np.concatenate([
            g,
            [spin[2, 1], spin[0, 2], spin[1, 0]],
            np.diag(G),
            [strain[0, 1], strain[1, 2], strain[0, 2]],
        ])


class StaticMotion(Motion):
    """No motion: `x(t) = x0`."""

    def affine(self, t):
        return np.eye(3), np.zeros(3)

    def rate(self, t):
        return np.zeros((3, 3)), np.zeros(3)

    def second_rate(self, t):
        return np.zeros((3, 3)), np.zeros(3)

    def to_dict(self):
        return {"type": "static"}


class RigidMotion(Motion):
    """A spin at constant angular velocity about a centre moving under constant acceleration.

    `x(t) = R(t) (x0 − c0) + c(t)` with `R(t) = exp(t [ω]×)` and
    `c(t) = c0 + u t + ½ gravity t²`. `centre c0 (3,)` world position at t = 0,
    `omega ω (3,)` rad per unit time, `velocity u (3,)`, `gravity (3,)` per unit time².
    Velocity `v = ω × (x − c(t)) + ċ(t)`; acceleration `ω × (ω × (x − c)) + gravity`.
    """

    def __init__(self, centre, omega=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0), gravity=(0.0, 0.0, 0.0)):
        self.centre = _vec("centre", centre)
        self.omega = _vec("omega", omega)
        self.velocity0 = _vec("velocity", velocity)
        self.gravity = _vec("gravity", gravity)

    def _state(self, t):
        R = Rotation.from_rotvec(self.omega * t).as_matrix()
        c = self.centre + self.velocity0 * t + 0.5 * self.gravity * t * t
        return R, c

    def affine(self, t):
        R, c = self._state(t)
        return R, c - R @ self.centre

    def rate(self, t):
        R, _ = self._state(t)
        R_dot = _cross_matrix(self.omega) @ R
        return R_dot, self.velocity0 + self.gravity * t - R_dot @ self.centre

    def second_rate(self, t):
        R, _ = self._state(t)
        W = _cross_matrix(self.omega)
        R_ddot = W @ W @ R
        return R_ddot, self.gravity - R_ddot @ self.centre

    def to_dict(self):
        return {"type": "rigid", "centre": self.centre.tolist(), "omega": self.omega.tolist(),
                "velocity": self.velocity0.tolist(), "gravity": self.gravity.tolist()}


class LinearFlowMotion(Motion):
    """A homogeneous deformation with a constant velocity gradient about a fixed centre.

    `x(t) = c + exp(t L) (x0 − c)`; `generator L (3, 3)` per unit time, `centre c (3,)`.
    Velocity `v = L (x − c)`, acceleration `L² (x − c)`; volume changes as
    `exp(t trace L)`, so a trace-free L (stretch `diag(k, −k/2, −k/2)`, pure shear) is
    incompressible.
    """

    def __init__(self, centre, generator):
        self.centre = _vec("centre", centre)
        self.generator = np.array(check_array("generator", np.asarray(generator, dtype=np.float64), (3, 3)))

    def affine(self, t):
        E = expm(t * self.generator)
        return E, self.centre - E @ self.centre

    def rate(self, t):
        E_dot = self.generator @ expm(t * self.generator)
        return E_dot, -E_dot @ self.centre

    def second_rate(self, t):
        E_ddot = self.generator @ self.generator @ expm(t * self.generator)
        return E_ddot, -E_ddot @ self.centre

    def to_dict(self):
        return {"type": "linear_flow", "centre": self.centre.tolist(), "generator": self.generator.tolist()}


class PeriodicFlowMotion(Motion):
    """A homogeneous deformation that oscillates: `x(t) = c + exp(sin(ω t) L) (x0 − c)`.

    `generator L (3, 3)` (the amplitude, in log-stretch units), `omega ω` rad per unit time,
    `centre c (3,)`. Velocity `v = ω cos(ω t) L (x − c)`: the strain rate reverses every half
    period, and the body returns to its canonical shape whenever `sin(ω t) = 0`. A trace-free
    L is incompressible. `Ä A⁻¹ = ω² (cos²(ω t) L² − sin(ω t) L)`.
    """

    def __init__(self, centre, generator, omega):
        self.centre = _vec("centre", centre)
        self.generator = np.array(check_array("generator", np.asarray(generator, dtype=np.float64), (3, 3)))
        self.omega = float(check_scalar("omega", omega))

    def affine(self, t):
        E = expm(np.sin(self.omega * t) * self.generator)
        return E, self.centre - E @ self.centre

    def rate(self, t):
        E_dot = self.omega * np.cos(self.omega * t) * self.generator @ self.affine(t)[0]
        return E_dot, -E_dot @ self.centre

    def second_rate(self, t):
        w, L = self.omega, self.generator
        E_ddot = w * w * (np.cos(w * t) ** 2 * L @ L - np.sin(w * t) * L) @ self.affine(t)[0]
        return E_ddot, -E_ddot @ self.centre

    def to_dict(self):
        return {"type": "periodic_flow", "centre": self.centre.tolist(), "generator": self.generator.tolist(),
                "omega": self.omega}


def motion_from_dict(description):
    """Rebuild a motion from `Motion.to_dict()`; raises ValueError naming `description`."""
    if not isinstance(description, dict) or "type" not in description:
        raise ValueError(f"description: expected a dict with a 'type', got {description!r}")
    kind = description["type"]
    args = {k: v for k, v in description.items() if k != "type"}
    try:
        if kind == "static":
            return StaticMotion(**args)
        if kind == "rigid":
            return RigidMotion(**args)
        if kind == "linear_flow":
            return LinearFlowMotion(**args)
        if kind == "periodic_flow":
            return PeriodicFlowMotion(**args)
    except TypeError as err:
        raise ValueError(f"description: bad fields for a {kind!r} motion ({err})") from None
    raise ValueError(f"description: unknown motion type {kind!r} (static, rigid, linear_flow, periodic_flow)")
