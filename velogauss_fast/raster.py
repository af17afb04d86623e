"""Rasterization of projected Gaussians: splat opacity, blending, the full image, in torch.

Twin of `velogauss_ref.raster` (spec/rendering.md, VG-ALPHA, VG-BLEND, VG-RENDER).

`rasterize` never evaluates a Gaussian at a pixel outside its box, nor at the box pixels
where its alpha is certainly below ALPHA_MIN: `row_spans` gives, per valid Gaussian in
depth order, each box row's interval inside its alpha >= ALPHA_MIN ellipse. Two backends
composite those pairs (a third, gsplat, lives in backends/gsplat_backend.py):

* "numba" (CPU; backends/numba_backend.py): compiled kernels walk the Gaussians in depth
  order and each one's row spans, keeping a running T per pixel; the backward walks
  them in reverse. No pair table, no sort; float64 throughout. Each view's VG-COV,
  VG-PROJ and VG-SH run in compiled kernels too (backends/numba_projection.py, `prepare_numba`),
  unless the camera needs a gradient, which they do not give, and so do its row spans
  (backends/numba_spans.py).
* "torch" (any device; the pair table in `velogauss_fast.spans`, the compositing and its
  backward in `velogauss_fast.composite`): the pairs are listed with vectorised index
  arithmetic (one record per Gaussian and box row), sorted once by (pixel, depth), and
  every pixel's run of the sorted table is composited at once:

  * transmittance before pair i of a pixel: T_i = exp(sum_{j<i} log(1 - alpha_j)), a
    segmented prefix sum taken as (cumulative sum over the chunk) - (its value at the
    pixel's first pair), accumulated in float64 whatever the working dtype. The running
    sum restarts near 0 at every pixel (each pixel's total is taken away at its last
    pair), so the absolute error of log T is ~1e-16 per pair times the pixel's own sum
    of |log(1 - alpha)|, however long the chunk: below 1e-9 for any run that matters (up
    to the stop that sum is below 14; tests/fast/test_raster.py pins it against exact
    per-pixel products on long runs, in a full-size chunk and across chunk boundaries);
  * exact early termination (VG-BLEND): pair i is blended iff alpha_i > 0 and
    T_i (1 - alpha_i) >= TRANSMITTANCE_MIN; the prefix sum only decreases, so the first
    pair that fails ends its pixel and every later pair of the pixel fails too;
  * an analytic backward (`Composite`, the 3DGS one) over the saved alpha and T of each
    pair, chunk by chunk, with the same restarting float64 sums within each pixel.
    `composite_autograd` is the same formulation left to autograd; tests compare the two,
    the benchmark times both (and numba).
"""

from typing import Literal, get_args

import torch
from torch import Tensor

from velogauss_core.checks import check_degree, check_size
from velogauss_core.constants import TRANSMITTANCE_MIN
from velogauss_core.rendering import RasterizeMode, check_mode, dilation, splat_opacities
from velogauss_fast.backends import gsplat_available, numba_available
from velogauss_fast.checks import check_array, check_finite
from velogauss_fast.composite import Composite, alpha_from_offsets, composite_autograd
from velogauss_fast.covariance import covariance_3d
from velogauss_fast.projection import project_gaussians
from velogauss_fast.sh import sh_to_color, viewing_directions
from velogauss_fast.spans import pair_table, row_spans

Backend = Literal["auto", "torch", "numba", "gsplat"]
_BACKENDS = get_args(Backend)


def splat_alpha(pixel, mean2d, conic, opacity):
    """Opacity of one splat at pixel centres: min(ALPHA_MAX, o exp(-sigma)) (VG-ALPHA).

    pixel: (..., 2) pixel centres (u, v); mean2d: (..., 2); conic: (..., 3) = (a, b, c) of
    the inverse 2D covariance; opacity: (...) in [0, 1] -> alpha (...), with
    sigma = (a du^2 + c dv^2) / 2 + b du dv. Skipped (alpha = 0, zero gradient) where
    sigma < 0 (a numerically indefinite conic) or alpha < ALPHA_MIN.
    """
    check_array("pixel", pixel, ("...", 2))
    check_array("mean2d", mean2d, ("...", 2))
    check_array("conic", conic, ("...", 3))
    check_array("opacity", opacity)
    return alpha_from_offsets(pixel - mean2d, conic, opacity)


def blend(colors, alphas, background):
    """Front-to-back alpha blending of the splats covering one pixel (VG-BLEND, paper eq. 2).

    colors: (M, 3); alphas: (M,) sorted by increasing depth (0 = skipped splat);
    background: (3,) -> (color (3,), T final transmittance (scalar)). A splat that would
    bring the transmittance below TRANSMITTANCE_MIN is not blended and ends the pixel.
    The running product is a cumulative product in input order, the same multiplications
    as the reference's loop.
    """
    check_array("colors", colors, (None, 3))
    check_array("alphas", alphas, (colors.shape[0],))
    check_array("background", background, (3,))
    # A skipped splat (alpha = 0) is no factor of the product at all, as in the reference's
    # loop: 1 instead of 1 - alpha, which has the same value but a gradient.
    t_incl = torch.cumprod(torch.where(alphas > 0, 1 - alphas, torch.ones_like(alphas)), dim=0)
    blended = (alphas > 0) & (t_incl >= TRANSMITTANCE_MIN)
    t_excl = torch.cat([torch.ones_like(t_incl[:1]), t_incl[:-1]])
    w = torch.where(blended, alphas * t_excl, torch.zeros_like(alphas))
    # The running product only decreases, so the smallest blended value is the last one.
    T = torch.where(blended, t_incl, torch.ones_like(t_incl)).amin() if len(alphas) else alphas.new_ones(())
    return (w[:, None] * colors).sum(0) + T * background, T


def rasterize(
    means: Tensor,  # [N, 3]
    quats: Tensor,  # [N, 4]
    scales: Tensor,  # [N, 3]
    opacities: Tensor,  # [N]
    colors: Tensor,  # [N, 3] or [N, K, 3]
    viewmat: Tensor,  # [4, 4]
    K: Tensor,  # [3, 3]
    width: int,
    height: int,
    background: Tensor | None = None,  # [3]
    sh_degree: int | None = None,
    backend: Backend = "auto",
    mode: RasterizeMode = "classic",
) -> tuple[Tensor, Tensor, dict]:
    """Render one image of N Gaussians, gsplat-style (VG-RENDER).

    means (N, 3), quats (N, 4) (w, x, y, z), scales (N, 3) standard deviations,
    opacities (N,) in [0, 1], colors (N, 3) RGB or (N, K, 3) SH coefficients when
    `sh_degree` is given, viewmat (4, 4) world-to-camera (OpenCV), K (3, 3), width and
    height in pixels, background (3,) (default black); all tensors of one dtype and device.
    backend: "torch" (vectorised pair table, any device), "numba" (compiled CPU kernels;
    ValueError for CUDA tensors or without numba), "gsplat" (CUDA kernels, tile-based; see
    velogauss_fast.backends.gsplat_backend; ValueError where CUDA or gsplat is missing) or
    "auto": gsplat when CUDA and gsplat are available, else numba for CPU tensors when numba
    is installed, else torch.
    mode: "classic" (3DGS: dilation EPS2D) or "antialiased" (Mip-Splatting's 2D filter:
    dilation MIP_FILTER_VARIANCE, each splat's opacity times VG-PROJ's compensation;
    velogauss_core.rendering), on every backend.
    Returns image (H, W, 3), alpha (H, W, 1) = 1 - T, and meta: the VG-PROJ outputs
    (mean2d, depth, cov2d, conic, radius, valid), "colors" (N, 3) the RGB used, and
    "n_pairs" the number of (Gaussian, pixel) pairs composited. meta["mean2d"] is part of
    the autograd graph: call meta["mean2d"].retain_grad() before backward to read the
    screen-space gradient used for densification.
    Invalid input (a bad shape, dtype or device, a NaN or an inf) raises ValueError naming
    the argument. N = 0 renders the background.
    """
    if backend not in _BACKENDS:
        raise ValueError(f"backend: expected one of {_BACKENDS}, got {backend!r}")
    check_mode(mode)
    check_array("means", means, (None, 3))
    n = means.shape[0]
    check_array("quats", quats, (n, 4))
    check_array("scales", scales, (n, 3))
    check_array("opacities", opacities, (n,))
    if sh_degree is None:
        check_array("colors", colors, (n, 3))
    else:
        check_degree("sh_degree", sh_degree)
        check_array("colors", colors, (n, None, 3))
        if colors.shape[1] < (sh_degree + 1) ** 2:
            raise ValueError(f"colors: sh_degree {sh_degree} needs {(sh_degree + 1) ** 2} "
                             f"SH coefficients, got {colors.shape[1]}")
    check_array("viewmat", viewmat, (4, 4))
    check_array("K", K, (3, 3))
    check_size("width", width)
    check_size("height", height)
    if background is None:
        background = means.new_zeros(3)
    check_array("background", background, (3,))
    for name, t in (("quats", quats), ("scales", scales), ("opacities", opacities), ("colors", colors),
                    ("viewmat", viewmat), ("K", K), ("background", background)):
        if t.dtype != means.dtype or t.device != means.device:
            raise ValueError(f"{name}: expected {means.dtype} on {means.device} like means, "
                             f"got {t.dtype} on {t.device}")
    # Finiteness is tested here, where the data enters, in one device sync for all eight
    # tensors; the functions below check shapes only (spec/conventions.md, "Bad input").
    check_finite(means=means, quats=quats, scales=scales, opacities=opacities, colors=colors, viewmat=viewmat, K=K,
                 background=background)

    if backend == "auto":
        backend = ("gsplat" if gsplat_available(means.device)
                   else "numba" if means.device.type == "cpu" and numba_available() else "torch")
    elif backend == "gsplat" and not gsplat_available(means.device):
        raise ValueError(f"backend: 'gsplat' needs CUDA tensors, a working CUDA device and the gsplat "
                         f"package; got tensors on {means.device}")
    elif backend == "numba" and not (means.device.type == "cpu" and numba_available()):
        raise ValueError(f"backend: 'numba' needs CPU tensors and the numba package; got tensors on {means.device}")
    if backend == "gsplat":
        from velogauss_fast.backends.gsplat_backend import rasterize_gsplat

        return rasterize_gsplat(means, quats, scales, opacities, colors, viewmat, K, width, height,
                                background, sh_degree, mode)
    prepare = spans = None
    if backend == "numba":
        from velogauss_fast.backends.numba_spans import row_spans_numba as spans

        if not (viewmat.requires_grad or K.requires_grad):
            from velogauss_fast.backends.numba_projection import prepare_numba as prepare
    return render_with_composite(means, quats, scales, opacities, colors, viewmat, K, width, height, background,
                                 sh_degree, COMPOSITES[backend], mode, prepare, spans)


def render_with_composite(means, quats, scales, opacities, colors, viewmat, K, width, height, background, sh_degree,
                          composite, mode="classic", prepare=None, spans=None):
    """`rasterize` on validated input with one of the COMPOSITES (the benchmark times each
    through this one pipeline) after `prepare` (None: `prepare_torch`; or the numba
    backend's `prepare_numba`) and `spans` (None: `velogauss_fast.spans.row_spans`; or the
    numba backend's `row_spans_numba`)."""
    prepare = prepare_torch if prepare is None else prepare
    proj, rgb, opacities = prepare(means, quats, scales, opacities, colors, viewmat, K, width, height, sh_degree,
                                   mode)
    spans = (row_spans if spans is None else spans)(proj["mean2d"], proj["conic"], opacities, proj["radius"],
                                                    proj["depth"], proj["valid"], width, height)
    image, T = composite(proj["mean2d"], proj["conic"], opacities, rgb, background, spans)
    meta = dict(proj, colors=rgb, n_pairs=spans.n_box)
    return image.reshape(height, width, 3), (1 - T).reshape(height, width, 1), meta


def prepare_torch(means, quats, scales, opacities, colors, viewmat, K, width, height, sh_degree, mode):
    """A view's VG-COV, VG-PROJ and VG-SH in torch operations: (VG-PROJ dict, rgb (N, 3),
    opacities (N,) as composited under `mode`). colors: (N, 3) RGB when sh_degree is None,
    else (N, K, 3) SH coefficients."""
    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height, dilation(mode))
    rgb = colors if sh_degree is None else sh_to_color(colors, viewing_directions(means, viewmat), sh_degree)
    return proj, rgb, splat_opacities(opacities, proj["compensation"], mode)


def _composite_torch(mean2d, conic, opacity, rgb, background, spans):
    """Vectorised torch compositing over the sorted pair table, analytic backward (any device)."""
    return Composite.apply(mean2d, conic, opacity, rgb, background, pair_table(spans))


def _composite_numba(mean2d, conic, opacity, rgb, background, spans):
    """Compiled Gaussian-major compositing, analytic backward (CPU; backends/numba_backend)."""
    from velogauss_fast.backends.numba_backend import CompositeNumba

    return CompositeNumba.apply(mean2d, conic, opacity, rgb, background, spans)


def _composite_plain_autograd(mean2d, conic, opacity, rgb, background, spans):
    """The torch backend's formulation with autograd's backward: the benchmark's baseline."""
    return composite_autograd(mean2d, conic, opacity, rgb, background, pair_table(spans))


# The compositing functions `render_with_composite` takes, by name: the backends of
# `rasterize`, and "autograd", the benchmark's baseline.
COMPOSITES = {"torch": _composite_torch, "numba": _composite_numba, "autograd": _composite_plain_autograd}
