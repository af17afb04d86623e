"""An analytic dynamic scene: textured bodies with exact motions, and its ground truth.

Ground truth is defined body by body. A world point `x` at time `t` belongs to the body
with the smallest `outside_distance` (0 inside; a lower bound of the Euclidean distance
outside), provided that distance is `≤ margin`; ties go to the body listed first. With the
default `margin = 0` only points inside (or on) a body belong to it; `margin = inf`
attributes every point to its nearest body. Points that belong to no body, and points of
static bodies, do not move: identity position, zero velocity and acceleration.
The catalog's bodies never overlap for t in [0, 1], so membership inside a body is
unambiguous there.
"""

import numpy as np

from velogauss.scenes.bodies import body_from_dict, cylinder_areas
from velogauss.scenes.raycast import render_rgba, render_sequence, shade, world_normal
from velogauss_core.checks import check_array, check_scalar
from velogauss_core.motion import EFFECTS


class AnalyticScene:
    """A named scene: `bodies` (list of `Body`), declared `effects` (subset of `EFFECTS`),
    `incompressible` (every motion preserves volume), a light (`light` (3,) direction
    towards it, `ambient` in [0, 1]) and the point the cameras look at, `look_at (3,)`."""

    def __init__(self, name, bodies, effects, incompressible, light=(0.3, -0.4, 1.0), ambient=0.45,
                 look_at=(0.0, 0.0, 0.0)):
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown:
            raise ValueError(f"effects: unknown effect(s) {unknown}; choose from {EFFECTS}")
        if not bodies:
            raise ValueError("bodies: a scene needs at least one body")
        light = np.asarray(check_array("light", np.asarray(light, dtype=np.float64), (3,)))
        if not 0.0 <= ambient <= 1.0:
            raise ValueError(f"ambient: expected a value in [0, 1], got {ambient!r}")
        self.name = name
        self.bodies = list(bodies)
        self.effects = list(effects)
        self.incompressible = bool(incompressible)
        self.light = light / np.linalg.norm(light)
        self.ambient = float(ambient)
        self.look_at = np.array(check_array("look_at", np.asarray(look_at, dtype=np.float64), (3,)))

    def body_index(self, x, t, margin=0.0):
        """Index `(N,)` of the body each world point `x (N, 3)` belongs to at time t, −1 for none
        (see the module docstring for the rule and `margin`, world units)."""
        x = np.asarray(check_array("x", x, (None, 3)), dtype=np.float64)
        check_scalar("t", t)
        distances = np.stack([body.outside_distance(x, t) for body in self.bodies], axis=1)
        nearest = np.argmin(distances, axis=1)
        return np.where(distances[np.arange(len(x)), nearest] <= margin, nearest, -1)

    def position(self, x0, t, margin=0.0):
        """World positions `(N, 3)` at time t of the material points at `x0 (N, 3)` at t = 0
        (membership decided at t = 0); identity for points of no body."""
        x0 = np.asarray(check_array("x0", x0, (None, 3)), dtype=np.float64)
        return self._per_body(x0, 0.0, margin, x0.copy(), lambda body, pts: body.motion.position(pts, t))

    def velocity(self, x, t, margin=0.0):
        """Eulerian velocity `(N, 3)` at world points `x (N, 3)`, time t (units per unit time)."""
        x = np.asarray(check_array("x", x, (None, 3)), dtype=np.float64)
        return self._per_body(x, t, margin, np.zeros_like(x), lambda body, pts: body.motion.velocity(pts, t))

    def acceleration(self, x, t, margin=0.0):
        """Material acceleration `Dv/Dt (N, 3)` at world points `x (N, 3)`, time t."""
        x = np.asarray(check_array("x", x, (None, 3)), dtype=np.float64)
        return self._per_body(x, t, margin, np.zeros_like(x), lambda body, pts: body.motion.acceleration(pts, t))

    def _per_body(self, x, t_member, margin, out, fn):
        owner = self.body_index(x, t_member, margin)
        for k, body in enumerate(self.bodies):
            mine = owner == k
            if np.any(mine):
                out[mine] = fn(body, x[mine])
        return out

    def bounds(self, t0=0.0, t1=1.0, n_times=101):
        """Axis-aligned box `(2, 3)` holding every body at `n_times` evenly spaced times in [t0, t1].

        Each body's box at one time is exact (`Body.aabb`); the catalog's motions are smooth
        and slow enough that 101 samples of [0, 1] miss less than 1e-4 of the extent.
        """
        boxes = np.array([body.aabb(t) for t in np.linspace(t0, t1, n_times) for body in self.bodies])
        return np.stack([boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)])

    def render(self, camera, t, supersample=1):
        """RGBA image `(H, W, 4)` of the scene at time t (see `raycast.render_rgba`)."""
        return render_rgba(self.bodies, camera, check_scalar("t", t), self.light, self.ambient, supersample)

    def render_sequence(self, camera, times, supersample=1):
        """RGBA images `(H, W, 4)` of the scene at each of `times` (a list), seen by one camera."""
        times = [check_scalar("t", t) for t in times]
        return render_sequence(self.bodies, camera, times, self.light, self.ambient, supersample)

    def sample_surface(self, n_points, rng):
        """`n_points` points on the bodies' surfaces at t = 0, shared in proportion to their
        approximate areas (box of `size`); returns world points, shaded colours and unit
        normals, each `(n_points, 3)`, with the colour the renderer gives that point at t = 0."""
        areas = np.array([_approximate_area(body) for body in self.bodies])
        counts = np.floor(n_points * areas / areas.sum()).astype(int)
        counts[np.argmax(areas)] += n_points - counts.sum()
        points, colors, normals = [], [], []
        for k, (body, count) in enumerate(zip(self.bodies, counts)):
            p, n_p = body.sample_surface(count, rng)
            L, o = body.to_world(0.0)
            n = world_normal(L, n_p)
            points.append(p @ L.T + o)
            normals.append(n)
            colors.append(shade(self.bodies, np.full(count, k), p, n, self.light, self.ambient))
        return np.concatenate(points), np.concatenate(colors), np.concatenate(normals)

    def to_dict(self):
        """A JSON-serialisable description of the whole scene (inverse of `from_dict`)."""
        return {
            "name": self.name,
            "effects": self.effects,
            "incompressible": self.incompressible,
            "light": self.light.tolist(),
            "ambient": self.ambient,
            "look_at": self.look_at.tolist(),
            "bodies": [body.to_dict() for body in self.bodies],
        }

    @classmethod
    def from_dict(cls, description):
        """Rebuild a scene from `to_dict()`; raises ValueError naming `description` when malformed."""
        try:
            return cls(
                name=description["name"],
                bodies=[body_from_dict(b) for b in description["bodies"]],
                effects=description["effects"],
                incompressible=description["incompressible"],
                light=description["light"],
                ambient=description["ambient"],
                look_at=description["look_at"],
            )
        except (KeyError, TypeError) as err:
            raise ValueError(f"description: malformed scene ({type(err).__name__}: {err})") from None


def _approximate_area(body):
    a, b, c = body.size
    if body.primitive == "plane":
        return 4.0 * a * b
    if body.primitive == "cylinder":
        return sum(cylinder_areas(body.size))
    box_area = 8.0 * (a * b + b * c + a * c)
    # A sphere's area is pi/6 of its bounding cube's; used for ellipsoids as well.
    return box_area * np.pi / 6.0 if body.primitive == "ellipsoid" else box_area
