"""Textured analytic bodies: a primitive placed at t = 0, a body-frame texture and a motion.

Primitive coordinates `p` describe a body independently of its size and motion:
`ellipsoid` is the unit ball `|p| ≤ 1`, `box` the cube `max |p_i| ≤ 1`, `cylinder` the solid
`p_x² + p_y² ≤ 1, |p_z| ≤ 1` (axis p_z), `plane` the square `|p_x|, |p_y| ≤ 1, p_z = 0`. The
placement maps them to canonical (t = 0 world) coordinates, `x0 = P p + c` with
`P = rotation · diag(size)`, and the motion to world coordinates at t, so `x = L(t) p + o(t)`
with `L = A P`, `o = A c + b`. Textures are functions of `p`: they are painted on the
material and move, rotate and stretch with it.
"""

from dataclasses import dataclass

import numpy as np

from velogauss.scenes.trajectories import Motion, motion_from_dict
from velogauss_core.checks import check_array
from velogauss_core.constants import POSE_ORTHONORMAL_TOL

PRIMITIVES = ("ellipsoid", "box", "cylinder", "plane")
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
        parity = (cells[:, 0] + cells[:, 1] + cells[:, 2] if self.kind == "checker" else cells[:, self.axis]) % 2
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
        `max(0, |p| − 1)` (ellipsoid, exact), `max(0, max_i |p_i| − 1)` (box),
        `max(0, |p_xy| − 1, |p_z| − 1)` (cylinder) or `max(0, |p_x| − 1, |p_y| − 1, |p_z|)`
        (plane); a linear map shrinks distances by at most its smallest singular value, which
        converts it to world units.
        """
        p = self.to_primitive(x, t)
        a = np.abs(p)
        if self.primitive == "ellipsoid":
            d = np.linalg.norm(p, axis=1) - 1.0
        elif self.primitive == "box":
            d = a.max(axis=1) - 1.0
        elif self.primitive == "cylinder":
            d = np.maximum(np.linalg.norm(p[:, :2], axis=1), a[:, 2]) - 1.0
        else:
            d = np.maximum(np.maximum(a[:, 0], a[:, 1]) - 1.0, a[:, 2])
        L, _ = self.to_world(t)
        return np.maximum(d, 0.0) * np.linalg.svd(L, compute_uv=False)[-1]

    def aabb(self, t):
        """The exact axis-aligned box `(2, 3)` of the body at time t.

        The image of the unit ball under `p ↦ L p + o` spans `o ± ‖L_i‖₂` along axis i; the
        image of the cube spans `o ± Σ_j |L_ij|`; the cylinder, a disc swept along p_z, spans
        `o ± (‖(L_i0, L_i1)‖₂ + |L_i2|)`; the square drops p_z.
        """
        L, o = self.to_world(t)
        half = half_extent(self.primitive, L)
        return np.stack([o - half, o + half])

    def sample_surface(self, n, rng):
        """`n` primitive-space surface points `(n, 3)` and outward primitive normals `(n, 3)`.

        Ellipsoid: uniform directions on the unit sphere. Box: faces drawn in proportion to
        their area at t = 0, uniform on each. Cylinder: side or caps in proportion to their
        approximate areas at t = 0, uniform in angle and height on the side, in area on the caps.
        Plane: uniform on the square, normal +z.
        """
        if self.primitive == "ellipsoid":
            p = rng.normal(size=(n, 3))
            p /= np.linalg.norm(p, axis=1, keepdims=True)
            return p, p.copy()
        if self.primitive == "plane":
            p = np.concatenate([rng.uniform(-1.0, 1.0, size=(n, 2)), np.zeros((n, 1))], axis=1)
            return p, np.tile([0.0, 0.0, 1.0], (n, 1))
        if self.primitive == "cylinder":
            return _cylinder_surface(self.size, n, rng)
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


def half_extent(primitive, L):
    """Half-widths `(..., 3)` along the world axes of `primitive`'s image under `p ↦ L p`, `L (..., 3, 3)`
    (see `Body.aabb`)."""
    if primitive == "ellipsoid":
        return np.linalg.norm(L, axis=-1)
    if primitive == "box":
        return np.abs(L).sum(axis=-1)
    if primitive == "cylinder":
        return np.linalg.norm(L[..., :2], axis=-1) + np.abs(L[..., 2])
    return np.abs(L[..., :2]).sum(axis=-1)


def cylinder_areas(size):
    """Approximate `(side, both caps)` areas of a cylinder of radii `size[:2]` and half-height `size[2]`
    (the side's perimeter by the quadratic mean of the radii)."""
    a, b, c = size
    return 2.0 * np.pi * np.sqrt(0.5 * (a * a + b * b)) * 2.0 * c, 2.0 * np.pi * a * b


def _cylinder_surface(size, n, rng):
    side, caps = cylinder_areas(size)
    on_side = rng.uniform(size=n) < side / (side + caps)
    angle = rng.uniform(0.0, 2.0 * np.pi, size=n)
    radius = np.where(on_side, 1.0, np.sqrt(rng.uniform(size=n)))  # sqrt: uniform in the disc's area
    z = np.where(on_side, rng.uniform(-1.0, 1.0, size=n), rng.choice([-1.0, 1.0], size=n))
    p = np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)
    normals = np.where(on_side[:, None], p * [1.0, 1.0, 0.0], p * [0.0, 0.0, 1.0])
    return p, normals


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
