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
Agreement is scale-relative: max |fast - ref| <= rtol * max |ref| per output, since an
elementwise relative error is meaningless at entries near zero. (tests/fast/motion/cases.py
has the same three checks for parameter dicts; these take plain arrays only.)
"""

import numpy as np
import torch
from autograd import make_vjp
from autograd.builtins import tuple as ag_tuple
from hypothesis import HealthCheck, settings

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
from velogauss_ref.projection import project_gaussians
from velogauss_ref.raster import rasterize as ref_rasterize

# float64: the same formulas up to reassociation (matrix products, sums of a few terms):
# a few ulps of the largest intermediate, so 1e-9 leaves ~1e5 headroom and still catches
# any formula error (1e-3 and up).
RTOL64 = 1e-9
# float32 vs the float64 reference: eps32 = 6e-8 times the condition of a few chained
# steps; observed below 1e-5 of the output scale for every function here.
RTOL32 = 1e-4

# The `device` fixture is function-scoped but constant per run: safe under hypothesis.
DEVICE_SETTINGS = settings(
    suppress_health_check=[*settings.default.suppress_health_check, HealthCheck.function_scoped_fixture]
)


def to_torch(x, dtype=torch.float64, device="cpu", requires_grad=False):
    return torch.tensor(np.asarray(x, dtype=np.float64), dtype=dtype, device=device, requires_grad=requires_grad)


def to_numpy(x):
    return x.detach().cpu().double().numpy()


def assert_close(actual, expected, rtol, name="", mask=None, floor=0.0):
    """max |actual - expected| <= rtol * max(max |expected|, floor) over `mask` (all if None).

    `floor` is the scale below which values count as zero (gradients that vanish
    identically come out as rounding noise of ~1e-16 in both implementations).
    """
    a = to_numpy(actual) if isinstance(actual, torch.Tensor) else np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    assert a.shape == e.shape, f"{name}: shape {a.shape} != {e.shape}"
    assert np.all(np.isfinite(a)), f"{name}: non-finite values"
    if mask is not None:
        a, e = a[mask], e[mask]
    if e.size == 0:
        return
    scale = max(float(np.max(np.abs(e))), floor, 1e-300)
    err = float(np.max(np.abs(a - e)))
    assert err <= rtol * scale, f"{name}: max abs error {err:.3e} > {rtol:.1e} * max|ref| {scale:.3e}"


def _tuple(out):
    return out if isinstance(out, tuple) else (out,)


def check_agreement(ref_fn, fast_fn, args, diff, device, seed=0, rtol=RTOL64, grad_rtol=RTOL64, floor=0.0):
    """Fast vs reference in float64: outputs, then gradients w.r.t. args[i], i in diff.

    args: NumPy arrays (converted) or static values (passed as they are); floor: the
    output scale below which values count as zero (see `assert_close`).
    """
    t_args = [to_torch(a, device=device, requires_grad=i in diff) if isinstance(a, np.ndarray) else a
              for i, a in enumerate(args)]
    out_f, out_r = _tuple(fast_fn(*t_args)), _tuple(ref_fn(*args))
    assert len(out_f) == len(out_r)
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float64 and f.device.type == torch.device(device).type
        assert_close(f, r, rtol, name=f"output {k}", floor=floor)
    if not diff:
        return
    rng = np.random.default_rng(seed)
    cot = tuple(rng.standard_normal(np.shape(r)) for r in out_r)

    def ref_selected(selected):
        full = list(args)
        for i, a in zip(diff, selected):
            full[i] = a
        out = ref_fn(*full)
        # A plain tuple of boxes is invisible to autograd (it would report zero
        # gradients); its own tuple type is traced.
        return ag_tuple(out) if isinstance(out, tuple) else out

    vjp, _ = make_vjp(ref_selected)(tuple(args[i] for i in diff))
    g_ref = vjp(cot if len(cot) > 1 else cot[0])
    total = sum((f * to_torch(c, device=device)).sum() for f, c in zip(out_f, cot))
    g_fast = torch.autograd.grad(total, [t_args[i] for i in diff], allow_unused=True)
    for i, gf, gr in zip(diff, g_fast, g_ref):
        gf = torch.zeros_like(t_args[i]) if gf is None else gf
        # Unit floor: these functions and cotangents are O(1), so are nonzero gradients.
        assert_close(gf, np.asarray(gr), grad_rtol, name=f"gradient of argument {i}", floor=1.0)


def check_float32(ref_fn, fast_fn, args, device, rtol=RTOL32, floor=0.0):
    """Fast in float32 vs the reference in float64 (outputs only; floor as in check_agreement).

    The floor is at least float32's smallest normal number over rtol: values below it are
    zero or denormal in float32 (a scale of 1e-89 squares to 0), so only an absolute error
    of that size is asked of them.
    """
    floor = max(floor, float(np.finfo(np.float32).tiny) / rtol)
    t_args = [to_torch(a, torch.float32, device) if isinstance(a, np.ndarray) else a for a in args]
    out_f, out_r = _tuple(fast_fn(*t_args)), _tuple(ref_fn(*args))
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float32
        assert_close(f, r, rtol, name=f"float32 output {k}", floor=floor)


def gradcheck_fn(fast_fn, args, diff, device, fast_mode=False):
    """torch.autograd.gradcheck of fast_fn in float64 w.r.t. args[i], i in diff.

    Callers keep the inputs away from every threshold of fast_fn (clamps, culling,
    skips): finite differences step 1e-6 across them. fast_mode checks <u, J v> for
    random u, v instead of the whole Jacobian (for functions with many outputs).
    """
    t_args = [to_torch(a, device=device) if isinstance(a, np.ndarray) else a for a in args]
    leaves = [t_args[i].clone().requires_grad_() for i in diff]

    def fn(*xs):
        full = list(t_args)
        for i, x in zip(diff, xs):
            full[i] = x
        return fast_fn(*full)

    assert torch.autograd.gradcheck(fn, tuple(leaves), eps=1e-6, atol=1e-6, rtol=1e-5, fast_mode=fast_mode)


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
    Sigma = covariance_3d(scene["quats"], scene["scales"])
    proj = project_gaussians(scene["means"], Sigma, scene["viewmat"], scene["K"], width, height)
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
    raw = scene["opacities"] * np.exp(-np.maximum(sigma, 0))
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
