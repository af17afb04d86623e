"""Analytic ray-caster of the synthetic scenes' bodies (vectorised NumPy; not the Gaussian rasterizer).

Each ray is carried into a body's primitive coordinates with the inverse of the body's
affine map at time t (`p = L⁻¹ (x − o)`, see `bodies.py`) and intersected with the unit
ball, cube or square there. Affine maps preserve the ray parameter, so the primitive-space
hit parameter is the world hit distance: rigid, stretched and sheared bodies are all
exact. Shading is Lambert with one directional light plus ambient light, evaluated with
each body's normals in its pose at t = 0 (the light turns with the body): a material point
keeps its colour as it moves, as the constant-colour Gaussians assume, so what changes
between frames is motion alone. (With a light fixed in the world, a spinning face
brightens and darkens by up to 55%, which the photometric loss would try to explain with
motion.)
"""

from dataclasses import dataclass

import numpy as np


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

    `primitive` in {"ellipsoid" (unit ball), "box" (cube [−1, 1]³), "plane" (square
    [−1, 1]² at z = 0)}, `origins`, `dirs (N, 3)` in primitive coordinates (`dirs` need not
    be unit). A ray starting inside a solid hits its exit point. Rays lying in a box face's
    plane or in the plane itself count as misses.
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
    axis = np.argmax(np.abs(p), axis=1)
    n = np.zeros_like(p)
    n[np.arange(len(p)), axis] = np.sign(p[np.arange(len(p)), axis])
    return n


def world_normal(L, n_p):
    """World unit normals `(N, 3)` of primitive normals `n_p (N, 3)` under `x = L p + o`: `L⁻ᵀ n_p`."""
    n = np.linalg.solve(L.T, n_p.T).T
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def cast_rays(bodies, origins, dirs, t):
    """Intersect world rays `origins, dirs (N, 3)` (unit dirs) with `bodies` at time t → `Hits`."""
    n = len(origins)
    best = np.full(n, np.inf)
    which = np.full(n, -1)
    point = np.zeros((n, 3))
    normal = np.zeros((n, 3))
    shading_normal = np.zeros((n, 3))
    for k, body in enumerate(bodies):
        L, o = body.to_world(t)
        L0, _ = body.to_world(0.0)
        o_p = np.linalg.solve(L, (origins - o).T).T
        d_p = np.linalg.solve(L, dirs.T).T
        s = intersect_primitive(body.primitive, o_p, d_p)
        closer = s < best
        if not np.any(closer):
            continue
        best[closer] = s[closer]
        which[closer] = k
        p = snap_to_surface(body.primitive, o_p[closer] + s[closer, None] * d_p[closer])
        point[closer] = p
        n_p = primitive_normal(body.primitive, p)
        normal[closer] = world_normal(L, n_p)
        shading_normal[closer] = world_normal(L0, n_p)
    facing_away = np.einsum("ij,ij->i", normal, dirs) > 0
    normal[facing_away] *= -1.0
    shading_normal[facing_away] *= -1.0
    return Hits(best, which, point, normal, shading_normal)


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
    origins, dirs = camera.pixel_rays(supersample)
    shape = dirs.shape[:2]
    hits = cast_rays(bodies, origins.reshape(-1, 3), dirs.reshape(-1, 3), t)
    rgb = shade(bodies, hits.body, hits.point, hits.shading_normal, light, ambient)
    covered = (hits.body >= 0).astype(np.float64)
    s = supersample
    h, w = shape[0] // s, shape[1] // s
    alpha = covered.reshape(h, s, w, s).mean(axis=(1, 3))
    rgb_sum = (rgb * covered[:, None]).reshape(h, s, w, s, 3).sum(axis=(1, 3))
    count = covered.reshape(h, s, w, s).sum(axis=(1, 3))
    rgb = np.divide(rgb_sum, count[..., None], out=np.zeros_like(rgb_sum), where=count[..., None] > 0)
    return np.concatenate([rgb, alpha[..., None]], axis=-1)
