"""Shared machinery of the representation/rendering fast-path tests (quaternion ... raster).

- `check_agreement`: fast (torch, float64) vs reference (NumPy): outputs, then gradients
  of <out, c> for a random cotangent c, torch autograd vs the reference's `autograd`;
- `check_float32`: fast in float32 vs the float64 reference;
- `gradcheck_fn`: torch.autograd.gradcheck of the fast function alone;
- small random scenes and `boundary_band`, the pixels of a render that sit within a band
  of a threshold (ALPHA_MIN, TRANSMITTANCE_MIN, box edges, integer radii, culling,
  depth ties), computed with the reference's own functions; `projection_doubt`, the
  Gaussians whose validity or integer radius sits within such a band;
- `render_gradients`: gradients of a whole render, reference (autograd) or fast (torch).
The three checks are tests/agreement.py's (shared with the motion tests), with the
rendering functions' gradient floor and gradcheck tolerances.
"""

import functools

import numpy as np
import torch
from autograd import make_vjp
from autograd.builtins import tuple as ag_tuple

from tests import agreement
from tests.agreement import (DEVICE_SETTINGS, RTOL32, RTOL64, assert_close, check_float32,  # noqa: F401
                             to_numpy, to_torch)
from tests.ref.cameras import intrinsics, rigid_viewmat, to_world
from velogauss_fast.raster import rasterize as fast_rasterize
from velogauss_core.constants import (
    ALPHA_MAX,
    ALPHA_MIN,
    EIGEN_DISCRIMINANT_FLOOR,
    FAR_PLANE,
    GAUSSIAN_EXTENT_SIGMA,
    NEAR_PLANE,
    TRANSMITTANCE_MIN,
)
from velogauss_ref.covariance import covariance_3d
from velogauss_core.rendering import dilation, splat_opacities
from velogauss_ref.projection import project_gaussians
from velogauss_ref.raster import rasterize as ref_rasterize

# Unit gradient floor: the rendering functions and their cotangents are O(1), so are their
# nonzero gradients; identically vanishing ones come out as rounding noise.
check_agreement = functools.partial(agreement.check_agreement, grad_floor=1.0)
# Every column of the Jacobian by default (these functions have few inputs), to 1e-6 / 1e-5.
gradcheck_fn = functools.partial(agreement.gradcheck_fn, fast_mode=False, atol=1e-6, rtol=1e-5)


# --- scenes ----------------------------------------------------------------------------

SCENE_KEYS = ("means", "quats", "scales", "opacities", "colors")


def random_scene(rng, n, width, height, scale_px=(0.5, 3.0), opacity=(0.05, 0.95), depth=(1.0, 4.0),
                 margin=3.0, sh_degree=None):
    """n random Gaussians seen by a random rigid camera: rasterize's positional arguments.

    Centres project inside the image widened by `margin` px, at depths in `depth`; each
    axis has a screen-space standard deviation in `scale_px` (before EPS2D); colours are
    RGB, or SH coefficients of degree `sh_degree`. Returns a dict of NumPy arrays plus
    width and height.
    """
    viewmat = rigid_viewmat(rng.uniform(-np.pi, np.pi, 3), rng.uniform(-1, 1, 3))
    f = rng.uniform(0.8, 1.2) * width
    K = intrinsics(f, f * rng.uniform(0.9, 1.1), width * rng.uniform(0.4, 0.6), height * rng.uniform(0.4, 0.6))
    uv = np.stack([rng.uniform(-margin, width + margin, n), rng.uniform(-margin, height + margin, n)], -1)
    z = rng.uniform(*depth, n)
    p = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * z, (uv[:, 1] - K[1, 2]) / K[1, 1] * z, z], -1)
    colors = (rng.uniform(size=(n, 3)) if sh_degree is None
              else rng.normal(scale=0.3, size=(n, (sh_degree + 1) ** 2, 3)))
    return {
        "means": to_world(p, viewmat),
        "quats": rng.normal(size=(n, 4)),
        "scales": rng.uniform(*scale_px, (n, 3)) * z[:, None] / f,
        "opacities": rng.uniform(*opacity, n),
        "colors": colors,
        "viewmat": viewmat,
        "K": K,
        "width": width,
        "height": height,
    }


def scene_to_torch(scene, dtype, device, requires_grad=False):
    return {k: (to_torch(v, dtype, device, requires_grad and k in SCENE_KEYS) if isinstance(v, np.ndarray) else v)
            for k, v in scene.items()}


def projection_doubt(proj, width, height, delta):
    """Gaussians whose VG-PROJ outcome may flip under a relative perturbation `delta`.

    proj: the reference's `project_gaussians` output. Returns three (N,) bool arrays:
    the depth test in doubt (depth within a relative delta of NEAR_PLANE or FAR_PLANE),
    the on-screen test in doubt (within delta (1 + |u|) px of flipping) and the radius
    in doubt (3 sqrt(lambda_max) within delta (1 + extent) of an integer).
    """
    u, v = proj["mean2d"][:, 0], proj["mean2d"][:, 1]
    r = proj["radius"].astype(np.float64)
    cov = proj["cov2d"]
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    b = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])
    extent = GAUSSIAN_EXTENT_SIGMA * np.sqrt(b + np.sqrt(np.maximum(EIGEN_DISCRIMINANT_FLOOR, b * b - det)))
    depth = proj["depth"]
    depth_doubt = (np.abs(depth - NEAR_PLANE) < delta * NEAR_PLANE) | (np.abs(depth - FAR_PLANE) < delta * FAR_PLANE)
    screen_doubt = (
        (np.abs(u + r) < delta * (1 + np.abs(u))) | (np.abs(u - r - width) < delta * (1 + np.abs(u)))
        | (np.abs(v + r) < delta * (1 + np.abs(v))) | (np.abs(v - r - height) < delta * (1 + np.abs(v)))
    )
    radius_doubt = np.abs(extent - np.round(extent)) < delta * (1 + extent)
    return depth_doubt, screen_doubt, radius_doubt


def boundary_band(scene, delta):
    """Pixels (H, W) bool whose value may jump under a perturbation of relative size `delta`.

    Computed from the reference's projection and a per-pixel replay of VG-RENDER. A pair
    (Gaussian, pixel) whose o exp(-sigma) is below (1 - delta) ALPHA_MIN is skipped
    whatever else happens, so only the other ("visible") pairs can move a pixel. A pixel
    is in the band when, for a Gaussian that is valid, or whose validity or radius is in
    doubt (`projection_doubt`; with a radius one larger, its box would reach the image),
      - its centre is within delta (1 + |u| + |v|) px of the box edge u +- r (or v +- r)
        and the pair is visible,
      - the radius is in doubt and the pixel is in the ring between the boxes of radius
        r - 1 and r + 1, the pair visible,
      - the on-screen test is in doubt and the pixel in its box widened by 1 px, the
        pair visible,
      - o exp(-sigma) is within a relative delta of ALPHA_MIN, or sigma within delta of
        its own terms' size of 0 (its sign may flip), the pixel in the box,
      - its depth is within a relative delta of the previous visible covering Gaussian's
        (the order may swap),
    or when the transmittance after one of its pairs is within a relative 10 delta of
    TRANSMITTANCE_MIN (T is a product of many factors, hence the wider band). A Gaussian
    whose depth test is in doubt puts the whole image in the band: the reference
    projected it with a stand-in depth, so where it would land is unknown.
    """
    width, height = scene["width"], scene["height"]
    mode = scene.get("mode", "classic")
    Sigma = covariance_3d(scene["quats"], scene["scales"])
    proj = project_gaussians(scene["means"], Sigma, scene["viewmat"], scene["K"], width, height, dilation(mode))
    depth_doubt, screen_doubt, radius_doubt = projection_doubt(proj, width, height, delta)
    if depth_doubt.any():
        return np.ones((height, width), bool)
    u, v = proj["mean2d"][:, 0], proj["mean2d"][:, 1]
    r = proj["radius"].astype(np.float64)
    depth = proj["depth"]
    depth_ok = (depth >= NEAR_PLANE) & (depth <= FAR_PLANE)
    reach = (u + r + 1 >= 0) & (u - r - 1 <= width) & (v + r + 1 >= 0) & (v - r - 1 <= height)
    considered = proj["valid"] | (depth_ok & (screen_doubt | (radius_doubt & reach)))

    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    px, py = jj.reshape(-1, 1), ii.reshape(-1, 1)  # (P, 1)
    du, dv = px - u, py - v  # (P, N)
    in_box = (np.abs(du) <= r) & (np.abs(dv) <= r)
    edge = np.minimum(np.abs(np.abs(du) - r), np.abs(np.abs(dv) - r))
    near_edge = edge < delta * (1 + np.abs(u) + np.abs(v))
    wide_box = (np.abs(du) <= r + 1) & (np.abs(dv) <= r + 1)
    ring = wide_box & ~((np.abs(du) <= r - 1) & (np.abs(dv) <= r - 1))
    a, bb, c = proj["conic"].T
    sigma = 0.5 * (a * du * du + c * dv * dv) + bb * du * dv
    sigma_terms = 0.5 * (np.abs(a) * du * du + np.abs(c) * dv * dv) + np.abs(bb * du * dv)
    opacity = splat_opacities(scene["opacities"], proj["compensation"], mode)
    raw = opacity * np.exp(-np.maximum(sigma, 0))
    visible = raw >= (1 - delta) * ALPHA_MIN
    near_alpha = (np.abs(raw - ALPHA_MIN) < delta * ALPHA_MIN) | (np.abs(sigma) < delta * sigma_terms)
    geometric = near_edge | (radius_doubt & ring) | (screen_doubt & wide_box)
    band = considered & ((in_box & near_alpha) | (visible & geometric))
    band = band.any(axis=1)  # (P,)

    # Depth ties between visible Gaussians covering the same pixel, and the transmittance replay.
    clamped = np.minimum(raw, ALPHA_MAX)
    alpha = np.where((sigma >= 0) & (clamped >= ALPHA_MIN), clamped, 0.0)
    covering = in_box & proj["valid"]
    T, done = np.ones(len(px)), np.zeros(len(px), bool)
    prev_depth = np.full(len(px), -np.inf)
    for g in np.argsort(depth, kind="stable"):
        cov_g = covering[:, g]
        band |= cov_g & visible[:, g] & (np.abs(depth[g] - prev_depth) < delta * np.abs(depth[g]))
        prev_depth = np.where(cov_g & visible[:, g], depth[g], prev_depth)
        active = cov_g & ~done & (alpha[:, g] > 0)
        t_next = T * (1 - alpha[:, g])
        band |= active & (np.abs(t_next - TRANSMITTANCE_MIN) < 10 * delta * TRANSMITTANCE_MIN)
        stop = active & (t_next < TRANSMITTANCE_MIN)
        done |= stop
        T = np.where(active & ~stop, t_next, T)
    return band.reshape(height, width)


# --- whole renders ---------------------------------------------------------------------

# The differentiable arguments of rasterize; scenes passed to `render_gradients` hold all six.
RENDER_GRAD_KEYS = (*SCENE_KEYS, "background")


def render_gradients(scene, cot_image, cot_alpha, device=None, backend="auto"):
    """Gradients of <image, cot_image> + <alpha, cot_alpha> w.r.t. RENDER_GRAD_KEYS of `scene`.

    device None: the reference's autograd through its per-pixel loop; else the fast path's
    torch autograd through `backend`, float64 on `device`. Returns a dict of NumPy arrays.
    """
    static = {k: v for k, v in scene.items() if k not in RENDER_GRAD_KEYS}
    if device is None:
        def render(xs):
            image, alpha, _ = ref_rasterize(**static, **dict(zip(RENDER_GRAD_KEYS, xs)))
            return ag_tuple((image, alpha))

        vjp, _ = make_vjp(render)(tuple(scene[k] for k in RENDER_GRAD_KEYS))
        return dict(zip(RENDER_GRAD_KEYS, vjp((cot_image, cot_alpha))))
    leaves = {k: to_torch(scene[k], device=device, requires_grad=True) for k in RENDER_GRAD_KEYS}
    static = {k: to_torch(v, device=device) if isinstance(v, np.ndarray) else v for k, v in static.items()}
    image, alpha, _ = fast_rasterize(**static, **leaves, backend=backend)
    total = (image * to_torch(cot_image, device=device)).sum() + (alpha * to_torch(cot_alpha, device=device)).sum()
    grads = torch.autograd.grad(total, list(leaves.values()), allow_unused=True)
    return {k: np.zeros(np.shape(scene[k])) if g is None else to_numpy(g) for k, g in zip(RENDER_GRAD_KEYS, grads)}
