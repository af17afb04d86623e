"""Analytic affine motions of the synthetic scenes' bodies.

A motion maps a material point's canonical position `x0` (its world position at `t = 0`)
to its world position at time `t`: `x(t) = A(t) x0 + b(t)`, with `A(0) = I`, `b(0) = 0`.
Because the map is affine, the Eulerian velocity and acceleration of the body are affine
fields of the world point `x`:

    v(x, t) = G(t) x + g(t),   G = Ȧ A⁻¹,  g = ḃ − G b
    a(x, t) = Ä A⁻¹ (x − b) + b̈        (material acceleration Dv/Dt)

so every body's motion is exactly one point of the paper's 12-dimensional affine basis
(VG-BASIS) at each time: see `basis_coefficients`. `BounceMotion` is smooth between bounces
only: its position is continuous, its rate jumps at a bounce and is reported just after it.
`MOTIONS` maps each `to_dict()["type"]` to its class.
"""

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from velogauss_core.checks import check_array, check_scalar
from velogauss_core.constants import POSE_ORTHONORMAL_TOL


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


class OrbitMotion(Motion):
    """A body whose centre orbits a pivot while the body spins at a rate of its own.

    `x(t) = R_s(t) (x0 − c0) + c(t)`, `c(t) = p + R_o(t) (c0 − p)`, with `R_o(t) = exp(t [Ω]×)`,
    `R_s(t) = exp(t [ω]×)`. `pivot p (3,)`, `centre c0 (3,)` the body's centre at t = 0,
    `orbit Ω (3,)` and `spin ω (3,)` angular velocities in rad per unit time (the spin is
    about the body's centre, along a world-fixed axis). Velocity `ω × (x − c) + Ω × (c − p)`.
    """

    def __init__(self, pivot, centre, orbit, spin=(0.0, 0.0, 0.0)):
        self.pivot = _vec("pivot", pivot)
        self.centre = _vec("centre", centre)
        self.orbit = _vec("orbit", orbit)
        self.spin = _vec("spin", spin)

    def _state(self, t):
        R_o = Rotation.from_rotvec(self.orbit * t).as_matrix()
        R_s = Rotation.from_rotvec(self.spin * t).as_matrix()
        return R_s, R_o @ (self.centre - self.pivot)

    def affine(self, t):
        R_s, arm = self._state(t)
        # Grouped so that b(0) = 0 exactly: the arm's turn, then the spin about the centre.
        return R_s, (arm - (self.centre - self.pivot)) + (self.centre - R_s @ self.centre)

    def rate(self, t):
        R_s, arm = self._state(t)
        R_dot = _cross_matrix(self.spin) @ R_s
        return R_dot, np.cross(self.orbit, arm) - R_dot @ self.centre

    def second_rate(self, t):
        R_s, arm = self._state(t)
        W = _cross_matrix(self.spin)
        R_ddot = W @ W @ R_s
        return R_ddot, np.cross(self.orbit, np.cross(self.orbit, arm)) - R_ddot @ self.centre

    def to_dict(self):
        return {"type": "orbit", "pivot": self.pivot.tolist(), "centre": self.centre.tolist(),
                "orbit": self.orbit.tolist(), "spin": self.spin.tolist()}


class PendulumMotion(Motion):
    """A rigid swing about a fixed hinge: the angle about the hinge axis is `θ(t) = θ0 cos(ω t + φ)`.

    `x(t) = h + R(t) (x0 − h)`, `R(t)` the rotation by `θ(t) − θ(0)` about the unit axis `n`
    (the body's pose at t = 0 is the one at angle θ(0)). `hinge h (3,)`, `axis (3,)` (any
    non-zero length; normalised), `amplitude θ0` rad, `omega ω` rad per unit time, `phase φ`
    rad. Velocity `θ̇ n × (x − h)`; `Ä = (θ̈ [n]× + θ̇² [n]×²) R`.
    """

    def __init__(self, hinge, axis, amplitude, omega, phase=0.0):
        self.hinge = _vec("hinge", hinge)
        self.axis = _vec("axis", axis)
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError("axis: must be non-zero")
        self.amplitude = float(check_scalar("amplitude", amplitude))
        self.omega = float(check_scalar("omega", omega))
        self.phase = float(check_scalar("phase", phase))
        self._n = _cross_matrix(self.axis / np.linalg.norm(self.axis))

    def _angles(self, t):
        """`(θ(t) − θ(0), θ̇, θ̈)`."""
        wt = self.omega * t + self.phase
        th = self.amplitude
        return (th * (np.cos(wt) - np.cos(self.phase)), -th * self.omega * np.sin(wt),
                -th * self.omega ** 2 * np.cos(wt))

    def _rotation(self, angle):
        N = self._n
        return np.eye(3) + np.sin(angle) * N + (1.0 - np.cos(angle)) * N @ N

    def affine(self, t):
        R = self._rotation(self._angles(t)[0])
        return R, self.hinge - R @ self.hinge

    def rate(self, t):
        angle, speed, _ = self._angles(t)
        R_dot = speed * self._n @ self._rotation(angle)
        return R_dot, -R_dot @ self.hinge

    def second_rate(self, t):
        angle, speed, accel = self._angles(t)
        R_ddot = (accel * self._n + speed ** 2 * self._n @ self._n) @ self._rotation(angle)
        return R_ddot, -R_ddot @ self.hinge

    def to_dict(self):
        return {"type": "pendulum", "hinge": self.hinge.tolist(), "axis": self.axis.tolist(),
                "amplitude": self.amplitude, "omega": self.omega, "phase": self.phase}


class OscillatingStretchMotion(Motion):
    """A stretch along three orthogonal axes, each oscillating with its own phase.

    `x(t) = c + Q diag(e_i(t)) Qᵀ (x0 − c)` with `e_i(t) = exp(k_i (sin(ω t + φ_i) − sin φ_i))`
    (so `e_i(0) = 1`). `centre c (3,)`, `axes Q (3, 3)` (columns: the stretch axes, a rotation),
    `amplitude k (3,)` in log-stretch units, `omega ω` rad per unit time, `phase φ (3,)` rad.
    Volume changes as `Π e_i`, so the motion is compressible unless the phases agree and Σ k_i = 0.
    """

    def __init__(self, centre, axes, amplitude, omega, phase=(0.0, 0.0, 0.0)):
        self.centre = _vec("centre", centre)
        self.axes = np.array(check_array("axes", np.asarray(axes, dtype=np.float64), (3, 3)))
        if np.max(np.abs(self.axes.T @ self.axes - np.eye(3))) > POSE_ORTHONORMAL_TOL:
            raise ValueError("axes: expected orthonormal columns")
        self.amplitude = _vec("amplitude", amplitude)
        self.omega = float(check_scalar("omega", omega))
        self.phase = _vec("phase", phase)

    def _factors(self, t):
        """`(e, ė, ë)`, each (3,)."""
        wt = self.omega * t + self.phase
        k, w = self.amplitude, self.omega
        e = np.exp(k * (np.sin(wt) - np.sin(self.phase)))
        return e, e * k * w * np.cos(wt), e * (k * k * w * w * np.cos(wt) ** 2 - k * w * w * np.sin(wt))

    def _matrix(self, diagonal):
        return (self.axes * diagonal) @ self.axes.T

    def affine(self, t):
        A = np.eye(3) + self._matrix(self._factors(t)[0] - 1.0)  # I + Q (e − 1) Qᵀ: exactly I at t = 0
        return A, self.centre - A @ self.centre

    def rate(self, t):
        A_dot = self._matrix(self._factors(t)[1])
        return A_dot, -A_dot @ self.centre

    def second_rate(self, t):
        A_ddot = self._matrix(self._factors(t)[2])
        return A_ddot, -A_ddot @ self.centre

    def to_dict(self):
        return {"type": "oscillating_stretch", "centre": self.centre.tolist(), "axes": self.axes.tolist(),
                "amplitude": self.amplitude.tolist(), "omega": self.omega, "phase": self.phase.tolist()}


class BounceMotion(Motion):
    """A body thrown under gravity that bounces on a horizontal floor, spinning about the vertical.

    The centre `c(t) = c0 + (u_x t, u_y t, z(t) − z0)`: `z` follows `z0 + u_z t − g t²/2` down to
    the contact height `floor`, then parabolas whose launch speed is the impact speed times the
    `restitution e`; after the bounces' total time `t1 + 2 v1 / (g (1 − e))` (t1 the first impact,
    v1 the first rebound speed) it rests at the floor. The body turns at `spin` rad per unit time
    about the vertical through its centre, which keeps its height, so it touches the floor at
    each bounce when `floor` is the centre's height above the ground at contact.
    `x(t) = R_z(spin t) (x0 − c0) + c(t)`. The position is continuous; the vertical velocity
    jumps from −v to e·v at a bounce, and at a bounce instant the motion reports the velocity just
    after it. `centre c0 (3,)`, `velocity u (3,)` at t = 0, `gravity g > 0` (along −z),
    `floor ≤ c0_z`, `restitution e` in [0, 1).
    """

    def __init__(self, centre, velocity, gravity, floor, restitution, spin=0.0):
        self.centre = _vec("centre", centre)
        self.velocity0 = _vec("velocity", velocity)
        self.gravity = float(check_scalar("gravity", gravity))
        self.floor = float(check_scalar("floor", floor))
        self.restitution = float(check_scalar("restitution", restitution))
        self.spin = float(check_scalar("spin", spin))
        if not self.gravity > 0:
            raise ValueError(f"gravity: expected > 0, got {gravity!r}")
        if not 0.0 <= self.restitution < 1.0:
            raise ValueError(f"restitution: expected a value in [0, 1), got {restitution!r}")
        if not self.floor <= self.centre[2]:
            raise ValueError(f"floor: must not be above the centre's height {self.centre[2]}, got {floor!r}")

    def first_impact(self):
        """The time of the first bounce and the rebound speed after it."""
        g, w, drop = self.gravity, self.velocity0[2], self.centre[2] - self.floor
        speed = np.sqrt(w * w + 2.0 * g * drop)
        return (w + speed) / g, self.restitution * speed

    def vertical(self, t):
        """`(z, ż, z̈)` of the centre at time t."""
        g, z0, w = self.gravity, self.centre[2], self.velocity0[2]
        start, speed = self.first_impact()
        if t < start:
            return z0 + w * t - 0.5 * g * t * t, w - g * t, -g
        rest = start + 2.0 * speed / (g * (1.0 - self.restitution))
        while t < rest and speed > 0:
            flight = 2.0 * speed / g
            if t < start + flight:
                s = t - start
                return self.floor + speed * s - 0.5 * g * s * s, speed - g * s, -g
            start, speed = start + flight, speed * self.restitution
        return self.floor, 0.0, 0.0

    def _spin(self, t):
        c, s = np.cos(self.spin * t), np.sin(self.spin * t)
        W = _cross_matrix([0.0, 0.0, self.spin])
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), W

    def affine(self, t):
        R, _ = self._spin(t)
        z, _, _ = self.vertical(t)
        c = self.centre + self.velocity0 * t
        c[2] = z
        return R, c - R @ self.centre

    def rate(self, t):
        R, W = self._spin(t)
        R_dot = W @ R
        c_dot = self.velocity0.copy()
        c_dot[2] = self.vertical(t)[1]
        return R_dot, c_dot - R_dot @ self.centre

    def second_rate(self, t):
        R, W = self._spin(t)
        R_ddot = W @ W @ R
        return R_ddot, np.array([0.0, 0.0, self.vertical(t)[2]]) - R_ddot @ self.centre

    def to_dict(self):
        return {"type": "bounce", "centre": self.centre.tolist(), "velocity": self.velocity0.tolist(),
                "gravity": self.gravity, "floor": self.floor, "restitution": self.restitution, "spin": self.spin}


def motion_from_dict(description):
    """Rebuild a motion from `Motion.to_dict()`; raises ValueError naming `description`."""
    if not isinstance(description, dict) or "type" not in description:
        raise ValueError(f"description: expected a dict with a 'type', got {description!r}")
    kind = description["type"]
    args = {k: v for k, v in description.items() if k != "type"}
    if kind not in MOTIONS:
        raise ValueError(f"description: unknown motion type {kind!r} ({', '.join(MOTIONS)})")
    try:
        return MOTIONS[kind](**args)
    except TypeError as err:
        raise ValueError(f"description: bad fields for a {kind!r} motion ({err})") from None


# Each motion's `to_dict()["type"]` and its class.
MOTIONS = {"static": StaticMotion, "rigid": RigidMotion, "linear_flow": LinearFlowMotion,
           "periodic_flow": PeriodicFlowMotion, "orbit": OrbitMotion, "pendulum": PendulumMotion,
           "oscillating_stretch": OscillatingStretchMotion, "bounce": BounceMotion}
