"""Textured analytic bodies: a primitive placed at t = 0, a body-frame texture and a motion.

Primitive coordinates `p` describe a body independently of its size and motion:
`ellipsoid` is the unit ball `|p| ≤ 1`, `box` the cube `max |p_i| ≤ 1`, `plane` the square
`|p_x|, |p_y| ≤ 1, p_z = 0`. The placement maps them to canonical (t = 0 world)
coordinates, `x0 = P p + c` with `P = rotation · diag(size)`, and the motion to world
coordinates at t, so `x = L(t) p + o(t)` with `L = A P`, `o = A c + b`. Textures are
functions of `p`: they are painted on the material and move, rotate and stretch with it.
"""

from dataclasses import dataclass

import numpy as np

from velogauss.scenes.trajectories import Motion, motion_from_dict
from velogauss_core.checks import check_array
from velogauss_core.constants import POSE_ORTHONORMAL_TOL

PRIMITIVES = ("ellipsoid", "box", "plane")
TEXTURES = ("checker", "stripes", "gradient")


@dataclass(frozen=True, eq=False)
class Texture:
    """A procedural albedo in primitive coordinates.

    `kind`: `checker` (3D checkerboard, `frequency` cells per unit of p), `stripes`
    (bands across `axis`), `gradient` (linear blend along `axis` from `colors[0]` at
    `p = −1` to `colors[1]` at `p = +1`). `colors`: two RGB triples in [0, 1].
    """

    kind: str
    colors: tuple
    axis: int = 0
    frequency: float = 2.0

    def __post_init__(self):
        if self.kind not in TEXTURES:
            raise ValueError(f"kind: unknown texture {self.kind!r}; choose one of {TEXTURES}")
        colors = np.asarray(check_array("colors", np.asarray(self.colors, dtype=np.float64), (2, 3)))
        if colors.min() < 0 or colors.max() > 1:
            raise ValueError("colors: RGB values must lie in [0, 1]")
        if self.axis not in (0, 1, 2):
            raise ValueError(f"axis: expected 0, 1 or 2, got {self.axis!r}")
        object.__setattr__(self, "colors", colors)

    def albedo(self, p):
        """RGB albedo `(N, 3)` at primitive coordinates `p (N, 3)`."""
        if self.kind == "gradient":
            w = np.clip(0.5 * (p[:, self.axis] + 1.0), 0.0, 1.0)[:, None]
            return (1.0 - w) * self.colors[0] + w * self.colors[1]
        cells = np.floor(self.frequency * p)
        parity = (cells.sum(axis=1) if self.kind == "checker" else cells[:, self.axis]) % 2
        return np.where(parity[:, None] == 0, self.colors[0], self.colors[1])

    def to_dict(self):
        """A JSON-serialisable description (inverse of `Texture(**d)`)."""
        return {"kind": self.kind, "colors": self.colors.tolist(), "axis": self.axis, "frequency": self.frequency}


@dataclass(frozen=True, eq=False)
class Body:
    """A named, textured primitive with its placement at t = 0 and its `motion`.

    `centre (3,)`, `size (3,)` positive (radii, half-sizes; the plane uses x, y and
    ignores z), `rotation (3, 3)` a rotation matrix, all at t = 0.
    """

    name: str
    primitive: str
    centre: np.ndarray
    size: np.ndarray
    rotation: np.ndarray
    texture: Texture
    motion: Motion

    def __post_init__(self):
        if self.primitive not in PRIMITIVES:
            raise ValueError(f"primitive: unknown primitive {self.primitive!r}; choose one of {PRIMITIVES}")
        centre = np.array(check_array("centre", np.asarray(self.centre, dtype=np.float64), (3,)))
        size = np.array(check_array("size", np.asarray(self.size, dtype=np.float64), (3,)))
        rotation = np.array(check_array("rotation", np.asarray(self.rotation, dtype=np.float64), (3, 3)))
        if size.min() <= 0:
            raise ValueError(f"size: must be positive, got {size.tolist()}")
        if np.max(np.abs(rotation.T @ rotation - np.eye(3))) > POSE_ORTHONORMAL_TOL or np.linalg.det(rotation) < 0:
            raise ValueError("rotation: expected a proper rotation matrix")
        object.__setattr__(self, "centre", centre)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "rotation", rotation)

    def to_world(self, t):
        """`(L (3, 3), o (3,))` with world position `x = L p + o` of primitive point `p` at time t."""
        A, b = self.motion.affine(t)
        P = self.rotation * self.size
        return A @ P, A @ self.centre + b

    def to_primitive(self, x, t):
        """Primitive coordinates `(N, 3)` of world points `x (N, 3)` at time t."""
        L, o = self.to_world(t)
        return np.linalg.solve(L, (x - o).T).T

    def outside_distance(self, x, t):
        """A lower bound `(N,)` of the world distance from `x (N, 3)` to the body at time t; 0 inside.

        In primitive space the distance to the solid is at least
        `max(0, |p| − 1)` (ellipsoid, exact), `max(0, max_i |p_i| − 1)` (box) or
        `max(0, |p_x| − 1, |p_y| − 1, |p_z|)` (plane); a linear map shrinks distances by at
        most its smallest singular value, which converts it to world units.
        """
        p = self.to_primitive(x, t)
        a = np.abs(p)
        if self.primitive == "ellipsoid":
            d = np.linalg.norm(p, axis=1) - 1.0
        elif self.primitive == "box":
            d = a.max(axis=1) - 1.0
        else:
            d = np.maximum(np.maximum(a[:, 0], a[:, 1]) - 1.0, a[:, 2])
        L, _ = self.to_world(t)
        return np.maximum(d, 0.0) * np.linalg.svd(L, compute_uv=False)[-1]

    def aabb(self, t):
        """The exact axis-aligned box `(2, 3)` of the body at time t.

        The image of the unit ball under `p ↦ L p + o` spans `o ± ‖L_i‖₂` along axis i; the
        image of the cube spans `o ± Σ_j |L_ij|`; the square drops p_z.
        """
        L, o = self.to_world(t)
        if self.primitive == "ellipsoid":
            half = np.linalg.norm(L, axis=1)
        elif self.primitive == "box":
            half = np.abs(L).sum(axis=1)
        else:
            half = np.abs(L[:, :2]).sum(axis=1)
        return np.stack([o - half, o + half])

    def sample_surface(self, n, rng):
        """`n` primitive-space surface points `(n, 3)` and outward primitive normals `(n, 3)`.

        Ellipsoid: uniform directions on the unit sphere. Box: faces drawn in proportion to
        their area at t = 0, uniform on each. Plane: uniform on the square, normal +z.
        """
        if self.primitive == "ellipsoid":
            p = rng.normal(size=(n, 3))
            p /= np.linalg.norm(p, axis=1, keepdims=True)
            return p, p.copy()
        if self.primitive == "plane":
            p = np.concatenate([rng.uniform(-1.0, 1.0, size=(n, 2)), np.zeros((n, 1))], axis=1)
            return p, np.tile([0.0, 0.0, 1.0], (n, 1))
        s = self.size
        face_areas = np.array([s[1] * s[2], s[0] * s[2], s[0] * s[1]])
        axis = rng.choice(3, size=n, p=face_areas / face_areas.sum())
        sign = rng.choice([-1.0, 1.0], size=n)
        p = rng.uniform(-1.0, 1.0, size=(n, 3))
        p[np.arange(n), axis] = sign
        normals = np.zeros((n, 3))
        normals[np.arange(n), axis] = sign
        return p, normals

    def to_dict(self):
        """A JSON-serialisable description (inverse of `body_from_dict`)."""
        return {"name": self.name, "primitive": self.primitive, "centre": self.centre.tolist(),
                "size": self.size.tolist(), "rotation": self.rotation.tolist(),
                "texture": self.texture.to_dict(), "motion": self.motion.to_dict()}


def body_from_dict(description):
    """Rebuild a `Body` from `Body.to_dict()`; raises ValueError naming `description` when malformed."""
    try:
        return Body(
            name=description["name"],
            primitive=description["primitive"],
            centre=description["centre"],
            size=description["size"],
            rotation=description["rotation"],
            texture=Texture(**description["texture"]),
            motion=motion_from_dict(description["motion"]),
        )
    except (KeyError, TypeError) as err:
        raise ValueError(f"description: malformed body ({type(err).__name__}: {err})") from None
