"""Analytic ray-caster of the synthetic scenes' bodies (vectorised NumPy; not the Gaussian rasterizer).

Each ray is carried into a body's primitive coordinates with the inverse of the body's
affine map at time t (`p = L⁻¹ (x − o)`, see `bodies.py`) and intersected with the unit
ball, cube, cylinder or square there. Affine maps preserve the ray parameter, so the
primitive-space hit parameter is the world hit distance: rigid, stretched and sheared bodies
are all exact. Shading is Lambert with one directional light plus ambient light, evaluated with
each body's normals in its pose at t = 0 (the light turns with the body): a material point
keeps its colour as it moves, as the constant-colour Gaussians assume, so what changes
between frames is motion alone. (With a light fixed in the world, a spinning face
brightens and darkens by up to 55%, which the photometric loss would try to explain with
motion.)
"""

from dataclasses import dataclass

import numpy as np

from velogauss.scenes.trajectories import StaticMotion


@dataclass(frozen=True, eq=False)
class Hits:
    """First hits of N rays: `distance (N,)` along the (unit) ray, inf on a miss;
    `body (N,)` index, −1 on a miss; `point (N, 3)` primitive coordinates and `normal
    (N, 3)` unit world normal facing the ray origin (both 0 on a miss); `shading_normal
    (N, 3)` the same surface point's normal in the body's pose at t = 0, on the same side."""

    distance: np.ndarray
    body: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    shading_normal: np.ndarray


def intersect_primitive(primitive, origins, dirs):
    """Ray parameter `s (N,)` of the first hit `origins + s dirs` with `s > 0`; inf on a miss.

    `primitive` in {"ellipsoid" (unit ball), "box" (cube [−1, 1]³), "cylinder" (`x² + y² ≤ 1`,
    `|z| ≤ 1`), "plane" (square [−1, 1]² at z = 0)}, `origins`, `dirs (N, 3)` in primitive
    coordinates (`dirs` need not be unit). A ray starting inside a solid hits its exit point.
    Rays lying in a box face's or a cylinder cap's plane, or in the plane itself, count as misses.
    """
    o, d = origins, dirs
    with np.errstate(divide="ignore", invalid="ignore"):
        if primitive == "ellipsoid":
            a = np.einsum("ij,ij->i", d, d)
            b = np.einsum("ij,ij->i", o, d)
            c = np.einsum("ij,ij->i", o, o) - 1.0
            root = np.sqrt(b * b - a * c)  # NaN where the line misses the ball
            near, far = (-b - root) / a, (-b + root) / a
            s = np.where(near > 0, near, np.where(far > 0, far, np.inf))
        elif primitive == "box":
            t1, t2 = (-1.0 - o) / d, (1.0 - o) / d
            entry = np.minimum(t1, t2).max(axis=1)
            exit_ = np.maximum(t1, t2).min(axis=1)
            s = np.where(entry > 0, entry, exit_)
            s = np.where((exit_ >= entry) & (s > 0), s, np.inf)
        elif primitive == "cylinder":
            # The infinite cylinder's interval along the ray, cut by the slab |z| ≤ 1.
            a = d[:, 0] ** 2 + d[:, 1] ** 2
            b = o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1]
            c = o[:, 0] ** 2 + o[:, 1] ** 2 - 1.0
            root = np.sqrt(b * b - a * c)  # NaN where the line misses the infinite cylinder
            axial = a == 0  # a ray along the axis is inside the side for every s, or never
            side_in = np.where(axial, np.where(c <= 0, -np.inf, np.nan), (-b - root) / a)
            side_out = np.where(axial, np.where(c <= 0, np.inf, np.nan), (-b + root) / a)
            z1, z2 = (-1.0 - o[:, 2]) / d[:, 2], (1.0 - o[:, 2]) / d[:, 2]
            entry = np.maximum(side_in, np.minimum(z1, z2))
            exit_ = np.minimum(side_out, np.maximum(z1, z2))
            s = np.where(entry > 0, entry, exit_)
            s = np.where((exit_ >= entry) & (s > 0), s, np.inf)
        elif primitive == "plane":
            s = -o[:, 2] / d[:, 2]
            hit = o[:, :2] + s[:, None] * d[:, :2]
            inside = np.all(np.abs(hit) <= 1.0, axis=1)
            s = np.where((s > 0) & inside, s, np.inf)
        else:
            raise ValueError(f"primitive: unknown primitive {primitive!r}")
    return np.where(np.isnan(s), np.inf, s)


def snap_to_surface(primitive, p):
    """Project primitive-space hit points `(N, 3)` exactly onto the surface.

    Rounding leaves a hit a few ulps off its surface; the textures take `floor` of the
    coordinates, and a face coordinate of 0.9999999 instead of 1 (or −1e-17 instead of 0
    on the plane) would flip the checker parity pixel by pixel.
    """
    p = p.copy()
    if primitive == "ellipsoid":
        return p / np.linalg.norm(p, axis=1, keepdims=True)
    if primitive == "plane":
        p[:, 2] = 0.0
        return p
    if primitive == "cylinder":
        on_cap = _on_cap(p)
        p[on_cap, 2] = np.sign(p[on_cap, 2])
        p[~on_cap, :2] /= np.linalg.norm(p[~on_cap, :2], axis=1, keepdims=True)
        return p
    axis = np.argmax(np.abs(p), axis=1)
    rows = np.arange(len(p))
    p[rows, axis] = np.sign(p[rows, axis])
    return p


def primitive_normal(primitive, p):
    """Outward unit normals `(N, 3)` in primitive coordinates at surface points `p (N, 3)`."""
    if primitive == "ellipsoid":
        return p / np.linalg.norm(p, axis=1, keepdims=True)
    if primitive == "plane":
        return np.tile([0.0, 0.0, 1.0], (len(p), 1))
    if primitive == "cylinder":
        on_cap = _on_cap(p)
        n = np.zeros_like(p)
        n[on_cap, 2] = np.sign(p[on_cap, 2])
        n[~on_cap, :2] = p[~on_cap, :2] / np.linalg.norm(p[~on_cap, :2], axis=1, keepdims=True)
        return n
    axis = np.argmax(np.abs(p), axis=1)
    n = np.zeros_like(p)
    n[np.arange(len(p)), axis] = np.sign(p[np.arange(len(p)), axis])
    return n


def _on_cap(p):
    """Which cylinder surface points `p (N, 3)` lie on a cap rather than the side: the nearer surface."""
    return np.abs(1.0 - np.abs(p[:, 2])) <= np.abs(1.0 - np.linalg.norm(p[:, :2], axis=1))


def world_normal(L, n_p):
    """World unit normals `(N, 3)` of primitive normals `n_p (N, 3)` under `x = L p + o`: `L⁻ᵀ n_p`."""
    n = n_p @ np.linalg.inv(L)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def cast_rays(bodies, origins, dirs, t, only=None, start=None):
    """Intersect world rays `origins (N, 3)` (or one shared origin `(3,)`), `dirs (N, 3)` (unit)
    with `bodies` at time t → `Hits`.

    `only`: the indices of the bodies to intersect (default: all); `start`: the `Hits` of the
    same rays with the other bodies, which a nearer hit replaces (a still body's hits serve
    every time). Only the rays that pass within a body's bounding sphere (about `o`, through
    the farthest corner of its primitive's bounding cube) are carried into its primitive
    coordinates: a body covers a small part of most images.
    """
    n = len(dirs)
    if start is None:
        best, which = np.full(n, np.inf), np.full(n, -1)
        point, normal, shading_normal = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    else:
        best, which, point = start.distance.copy(), start.body.copy(), start.point.copy()
        normal, shading_normal = start.normal.copy(), start.shading_normal.copy()
    for k in range(len(bodies)) if only is None else only:
        body = bodies[k]
        L, o = body.to_world(t)
        L0, _ = body.to_world(0.0)
        rows = _near_rays(origins, dirs, o, np.linalg.norm(_CUBE_CORNERS @ L.T, axis=1).max())
        if len(rows) == 0:
            continue
        inverse = np.linalg.inv(L)
        o_p = (origins - o if origins.ndim == 1 else origins[rows] - o) @ inverse.T
        d_p = dirs[rows] @ inverse.T
        o_p = np.broadcast_to(o_p, d_p.shape)
        s = intersect_primitive(body.primitive, o_p, d_p)
        closer = s < best[rows]
        if not np.any(closer):
            continue
        hit = rows[closer]
        best[hit] = s[closer]
        which[hit] = k
        p = snap_to_surface(body.primitive, o_p[closer] + s[closer, None] * d_p[closer])
        point[hit] = p
        n_p = primitive_normal(body.primitive, p)
        normal[hit] = world_normal(L, n_p)
        shading_normal[hit] = world_normal(L0, n_p)
    hit = np.flatnonzero(which >= 0)
    facing_away = hit[np.einsum("ij,ij->i", normal[hit], dirs[hit]) > 0]
    normal[facing_away] *= -1.0
    shading_normal[facing_away] *= -1.0
    return Hits(best, which, point, normal, shading_normal)


# The unit cube's corners: their images bound every primitive's.
_CUBE_CORNERS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
# Widens the bounding sphere so that rounding never drops a ray that grazes it.
_SPHERE_SLACK = 1.0 + 1e-6


def _near_rays(origins, dirs, centre, radius):
    """Indices of the rays (unit `dirs`) that pass within `radius` of `centre` ahead of their origin."""
    w = centre - origins
    if w.ndim == 1:  # one shared origin: one matrix-vector product
        along, distance2 = dirs @ w, w @ w
    else:
        along, distance2 = np.einsum("ij,ij->i", w, dirs), np.einsum("ij,ij->i", w, w)
    reach2 = (radius * _SPHERE_SLACK) ** 2
    return np.flatnonzero((distance2 - along * along <= reach2) & ((along > 0) | (distance2 <= reach2)))


def shade(bodies, body_index, point, normal, light, ambient):
    """Lambert colour `(N, 3)`: `albedo · (ambient + (1 − ambient) max(0, n·light))`.

    `body_index (N,)` (−1 gives black), `point (N, 3)` primitive coordinates, `normal
    (N, 3)` unit world normals (the shading normals of `Hits`), `light (3,)` unit direction towards the light,
    `ambient` in [0, 1].
    """
    rgb = np.zeros((len(body_index), 3))
    lambert = ambient + (1.0 - ambient) * np.clip(normal @ light, 0.0, None)
    for k, body in enumerate(bodies):
        mine = body_index == k
        if np.any(mine):
            rgb[mine] = body.texture.albedo(point[mine]) * lambert[mine, None]
    return rgb


def render_rgba(bodies, camera, t, light, ambient, supersample=1):
    """Render `bodies` at time t seen by `camera` (velogauss.data.cameras.Camera) → `(H, W, 4)`.

    RGB is the average colour of the sub-pixel rays that hit a body (0 where none does),
    alpha the fraction that hit, over a `supersample × supersample` grid per pixel
    (`supersample = 1`: one ray through the pixel centre). Compositing over a background
    `bg` as `rgb·a + bg·(1 − a)` gives the anti-aliased image.
    """
    return render_sequence(bodies, camera, [t], light, ambient, supersample)[0]


def render_sequence(bodies, camera, times, light, ambient, supersample=1):
    """`render_rgba` at each of `times`, the camera's rays computed once: a list of `(H, W, 4)`."""
    _, dirs = camera.pixel_rays(supersample)
    shape = dirs.shape[:2]
    dirs = dirs.reshape(-1, 3)
    s = supersample
    h, w = shape[0] // s, shape[1] // s
    still = [k for k, body in enumerate(bodies) if isinstance(body.motion, StaticMotion)]
    moving = [k for k in range(len(bodies)) if k not in still]
    # The still bodies' hits and colours are the same at every time; the moving bodies' are redone.
    background = cast_rays(bodies, camera.centre, dirs, 0.0, only=still)
    background_rgb = shade(bodies, background.body, background.point, background.shading_normal, light, ambient)
    images = []
    for t in times:
        hits = cast_rays(bodies, camera.centre, dirs, t, only=moving, start=background)
        rgb = background_rgb.copy()
        redo = np.flatnonzero(np.isin(hits.body, moving))
        rgb[redo] = shade(bodies, hits.body[redo], hits.point[redo], hits.shading_normal[redo], light, ambient)
        covered = (hits.body >= 0).astype(np.float64)
        samples = np.concatenate([rgb * covered[:, None], covered[:, None]], axis=1).reshape(h, s, w, s, 4)
        # One sum of whole sub-images per sub-pixel offset: far faster than reducing strided axes.
        total = sum(samples[:, a, :, b] for a in range(s) for b in range(s))
        rgb_sum, count = total[..., :3], total[..., 3:]
        rgb = np.divide(rgb_sum, count, out=np.zeros_like(rgb_sum), where=count > 0)
        images.append(np.concatenate([rgb, count / (s * s)], axis=-1))
    return images
