"""Rasterization of projected Gaussians: splat opacity, blending, the full image, in torch.

Twin of `velogauss_ref.raster` (spec/rendering.md, VG-ALPHA, VG-BLEND, VG-RENDER).

`rasterize` never evaluates a Gaussian at a pixel outside its box, nor at the box pixels
where its alpha is certainly below ALPHA_MIN: `_row_spans` gives, per valid Gaussian in
depth order, each box row's interval inside its alpha >= ALPHA_MIN ellipse. Two backends
composite those pairs (a third, gsplat, lives in backends/gsplat_backend.py):

* "numba" (CPU; backends/numba_backend.py): compiled kernels walk the Gaussians in depth
  order and each one's row spans, keeping a running T per pixel; the backward walks
  them in reverse. No pair table, no sort; float64 throughout.
* "torch" (any device; this module): the pairs are listed with vectorised index
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
  * an analytic backward (`_Composite`, the 3DGS one) over the saved alpha and T of each
    pair, chunk by chunk, with the same restarting float64 sums within each pixel.
    `_composite_autograd` is the same formulation left to autograd; tests compare the two,
    the benchmark times both (and numba).
"""

import math
from typing import NamedTuple

import torch

from velogauss_fast.backends import gsplat_available, numba_available
from velogauss_fast.checks import check_array
from velogauss_fast.covariance import covariance_3d
from velogauss_fast.projection import project_gaussians
from velogauss_fast.sh import sh_to_color, viewing_directions
from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN
from velogauss_core.checks import check_degree, check_size

# Pairs composited per chunk: bounds the temporaries of forward and backward (about 100
# bytes per pair) to ~25 MB while keeping the per-chunk Python overhead negligible. Measured
# on W3 (velogauss.bench.raster, 2 threads): 1<<18 took 0.33 s and 180 MiB forward+backward,
# 1<<20 0.37 s and 219 MiB, 1<<16 0.44 s (the loop overhead starts to show).
_CHUNK_PAIRS = 1 << 18
_LOG_TRANSMITTANCE_MIN = math.log(TRANSMITTANCE_MIN)
_BACKENDS = ("auto", "torch", "numba", "gsplat")


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
    return _alpha_from_offsets(pixel - mean2d, conic, opacity)


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
    means,
    quats,
    scales,
    opacities,
    colors,
    viewmat,
    K,
    width,
    height,
    background=None,
    sh_degree=None,
    backend="auto",
):
    """Render one image of N Gaussians, gsplat-style (VG-RENDER).

    means (N, 3), quats (N, 4) (w, x, y, z), scales (N, 3) standard deviations,
    opacities (N,) in [0, 1], colors (N, 3) RGB or (N, K, 3) SH coefficients when
    `sh_degree` is given, viewmat (4, 4) world-to-camera (OpenCV), K (3, 3), width and
    height in pixels, background (3,) (default black); all tensors of one dtype and device.
    backend: "torch" (this module), "gsplat" (CUDA kernels, tile-based; see
    velogauss_fast.backends.gsplat_backend; ValueError where CUDA or gsplat is missing) or
    "auto" (gsplat when CUDA and gsplat are available, else torch).
    Returns image (H, W, 3), alpha (H, W, 1) = 1 - T, and meta: the VG-PROJ outputs
    (mean2d, depth, cov2d, conic, radius, valid), "colors" (N, 3) the RGB used, and
    "n_pairs" the number of (Gaussian, pixel) pairs composited. meta["mean2d"] is part of
    the autograd graph: call meta["mean2d"].retain_grad() before backward to read the
    screen-space gradient used for densification.
    Invalid input raises ValueError naming the argument. N = 0 renders the background.
    """
    if backend not in _BACKENDS:
        raise ValueError(f"backend: expected one of {_BACKENDS}, got {backend!r}")
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
                                background, sh_degree)
    return _render(means, quats, scales, opacities, colors, viewmat, K, width, height, background, sh_degree,
                   COMPOSITES[backend])


def _render(means, quats, scales, opacities, colors, viewmat, K, width, height, background, sh_degree, composite):
    """`rasterize` on validated input with one of the COMPOSITES (the benchmark times each
    through this one pipeline)."""
    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height)
    if sh_degree is None:
        rgb = colors
    else:
        rgb = sh_to_color(colors, viewing_directions(means, viewmat), sh_degree)
    spans = _row_spans(proj["mean2d"], proj["conic"], opacities, proj["radius"], proj["depth"], proj["valid"],
                       width, height)
    image, T = composite(proj["mean2d"], proj["conic"], opacities, rgb, background, spans)
    meta = dict(proj, colors=rgb, n_pairs=spans.n_box)
    return image.reshape(height, width, 3), (1 - T).reshape(height, width, 1), meta


def _composite_torch(mean2d, conic, opacity, rgb, background, spans):
    """Vectorised torch compositing over the sorted pair table, analytic backward (any device)."""
    return _Composite.apply(mean2d, conic, opacity, rgb, background, _pair_table(spans))


def _composite_numba(mean2d, conic, opacity, rgb, background, spans):
    """Compiled Gaussian-major compositing, analytic backward (CPU; backends/numba_backend)."""
    from velogauss_fast.backends.numba_backend import CompositeNumba

    return CompositeNumba.apply(mean2d, conic, opacity, rgb, background, spans)


def _composite_plain_autograd(mean2d, conic, opacity, rgb, background, spans):
    """The torch backend's formulation with autograd's backward: the benchmark's baseline."""
    return _composite_autograd(mean2d, conic, opacity, rgb, background, _pair_table(spans))


class _Spans(NamedTuple):
    """Per valid Gaussian, in depth order, what is needed to list and composite its pairs row by row."""

    ids: torch.Tensor  # [n] int64 Gaussian index, sorted by (depth, index)
    geom: torch.Tensor  # [n, 15] float64: the SPAN_COLUMNS below
    width: int
    height: int
    n_box: int  # (valid Gaussian, pixel) pairs whose box holds the centre, pruned or not


# Columns of _Spans.geom: the mean, conic and opacity, then the row spans: sigma <= s  <=>
# a du^2 + 2 b dv du + c dv^2 <= 2 s, so the row at offset dv from the mean keeps du in
# centre +- half with centre = u - (b / a) dv and half = sqrt(2 a s - det dv^2) / a
# (det = a c - b^2); "definite" is 0 for a conic that is not numerically positive definite
# (its rows keep the whole box); x0..y1 the box.
SPAN_COLUMNS = ("u", "v", "a", "b", "c", "opacity", "two_as", "det", "inv_a", "b_over_a", "definite",
                "x0", "x1", "y0", "y1")
# Integer views whose order is that of positive floats of the same width.
_BITS = {torch.float16: torch.int16, torch.bfloat16: torch.int16, torch.float32: torch.int32,
         torch.float64: torch.int64}


def _row_spans(mean2d, conic, opacity, radius, depth, valid, width, height):
    """The row-span parameters of every valid Gaussian, in depth order (see `_Spans`).

    A pair of VG-RENDER is a valid Gaussian and a pixel centre inside its box. Pairs with
    alpha < ALPHA_MIN are skipped by VG-ALPHA and change nothing (not even T), so only the
    pixels of each box row where sigma <= log(opacity / ALPHA_MIN) + margin are listed:
    an interval of the row (the conic's ellipse), computed per (Gaussian, row) in float64
    by `_pair_table` here and by the numba kernels' `row_span`, with the same operations.
    The margin (`_span_margin`) exceeds the rounding of sigma in the working dtype, so
    every dropped pair has a computed alpha < ALPHA_MIN; kept pairs may still be skipped.
    Ties in depth keep index order (stable sort).
    """
    with torch.no_grad():
        f64 = torch.float64
        ids = torch.nonzero(valid).squeeze(1)
        # Valid depths are >= NEAR_PLANE > 0, and positive floats order as their bit
        # patterns: a stable (radix) sort of the integer view is the stable depth order,
        # ~10x faster on the CPU than sorting the floats.
        d = depth.index_select(0, ids)
        ids = ids.index_select(0, torch.sort(d.view(_BITS[d.dtype]), stable=True).indices)
        # One gather of the per-Gaussian inputs, then contiguous columns.
        cols = torch.cat([mean2d, conic, opacity[:, None], radius[:, None].to(mean2d.dtype)], dim=1)
        u, v, a, b, c, o, r = cols.index_select(0, ids).T.contiguous()
        x0, x1 = _centre_span(u - r, u + r, width)
        y0, y1 = _centre_span(v - r, v + r, height)
        n_box = int(((x1 - x0 + 1).clamp(min=0) * (y1 - y0 + 1).clamp(min=0)).sum())
        u, v, a, b, c, o, r = (t.to(f64) for t in (u, v, a, b, c, o, r))
        s = torch.log(o / ALPHA_MIN) + _span_margin(a, b, c, r, mean2d.dtype)
        det = a * c - b * b
        definite = (a > 0) & (det > 0)
        a_safe = torch.where(definite, a, torch.ones_like(a))
        geom = torch.stack([u, v, a, b, c, o, 2 * a * s, det, 1 / a_safe, b / a_safe, definite.to(f64),
                            x0.to(f64), x1.to(f64), y0.to(f64), y1.to(f64)], dim=1)
    return _Spans(ids, geom, width, height, n_box)


class _Pairs(NamedTuple):
    """(Gaussian, pixel) pairs sorted by (pixel, depth, index); pixel = row * width + col."""

    gid: torch.Tensor  # [M] int64 Gaussian index
    pix: torch.Tensor  # [M] int64 flat pixel index, non-decreasing
    offsets: torch.Tensor  # [P + 1] int64: the pairs of pixel p are offsets[p]:offsets[p+1]
    width: int
    height: int
    n_box: int  # as in _Spans


def _pair_table(spans):
    """The (Gaussian, pixel) pairs of `spans` (see `_row_spans`), sorted by (pixel, depth).

    Pairs are generated Gaussian by Gaussian in depth order, so one stable sort on the
    int32 pixel index yields (pixel, depth) order.
    """
    with torch.no_grad():
        device, n_pix, width = spans.geom.device, spans.width * spans.height, spans.width
        ids = spans.ids
        u, v, _, _, _, _, two_as, det, inv_a, b_over_a, definite, x0, x1, y0, y1 = spans.geom.unbind(1)
        ny = (y1 - y0 + 1).clamp(min=0).to(torch.int64)
        per_gaussian = torch.stack([u, v, two_as, det, inv_a, b_over_a, definite, y0, x0, x1])

        # One record per (Gaussian, box row).
        n_rec = int(ny.sum())
        (u_r, v_r, two_as, det_r, inv_a, b_over_a, definite_r, y0_r, x0_r, x1_r) = torch.repeat_interleave(
            per_gaussian, ny, dim=1, output_size=n_rec)
        row = y0_r + (torch.arange(n_rec, device=device) - torch.repeat_interleave(torch.cumsum(ny, 0) - ny, ny,
                                                                                   output_size=n_rec))
        dv = row + 0.5 - v_r
        disc = two_as - det_r * dv * dv
        half = torch.sqrt(torch.clamp(disc, min=0)) * inv_a
        centre = u_r - b_over_a * dv
        xa = torch.maximum(torch.ceil(centre - half - 0.5).clamp(-1.0, width + 1.0), x0_r)
        xb = torch.minimum(torch.floor(centre + half - 0.5).clamp(-1.0, width + 1.0), x1_r)
        xb = torch.where(disc < 0, xa - 1, xb)
        # A conic that is not numerically positive definite keeps its whole box row.
        indefinite = definite_r == 0
        xa = torch.where(indefinite, x0_r, xa).to(torch.int64)
        xb = torch.where(indefinite, x1_r, xb).to(torch.int64)
        cnt = (xb - xa + 1).clamp(min=0)

        # Pair k of a record is pixel row * width + xa + k: the record's first pixel minus
        # its first pair index, expanded, plus the global pair index.
        m = int(cnt.sum())
        start = row.to(torch.int64) * width + xa - (torch.cumsum(cnt, 0) - cnt)
        pix = torch.repeat_interleave(start, cnt, output_size=m)
        pix += torch.arange(m, device=device)
        pix, order = torch.sort(pix.to(torch.int32), stable=True)
        pix = pix.to(torch.int64)
        gid = torch.repeat_interleave(torch.repeat_interleave(ids, ny, output_size=n_rec), cnt, output_size=m)
        gid = gid.index_select(0, order)
        del order
        offsets = torch.zeros(n_pix + 1, dtype=torch.int64, device=device)
        torch.cumsum(torch.bincount(pix, minlength=n_pix), 0, out=offsets[1:])
    return _Pairs(gid, pix, offsets, spans.width, spans.height, spans.n_box)


# Slack (in units of sigma) added to the pruning bound log(opacity / ALPHA_MIN): far above
# the float64 rounding of the bound itself, it keeps pruning conservative when the
# compositing later recomputes alpha in the working dtype (see `_span_margin`).
_SPAN_SIGMA_SLACK = 0.01


def _span_margin(a, b, c, r, dtype):
    """Slack on sigma covering its rounding in `dtype`: sigma sums terms up to
    (a + c + 2|b|)(r + 1)^2 / 2 (offsets up to the box radius), each rounded to a few eps."""
    eps = torch.finfo(dtype).eps
    return _SPAN_SIGMA_SLACK + 8 * eps * (a.abs() + c.abs() + 2 * b.abs()) * (r + 1) ** 2


def _centre_span(lo, hi, n):
    """Integer range [j0, j1] of pixel indices j in [0, n) with lo <= j + 0.5 <= hi.

    lo, hi are compared with j + 0.5 in their own dtype, exactly as a per-pixel test would,
    so the span agrees with the reference's membership test bit for bit. Clamping to
    [-1, n + 1] first changes no membership within [0, n) and keeps casts in range.
    """
    lo = lo.clamp(-1.0, n + 1.0)
    hi = hi.clamp(-1.0, n + 1.0)
    j0 = torch.ceil(lo - 0.5).to(torch.int64)
    j0 = torch.where((j0 - 1).to(lo.dtype) + 0.5 >= lo, j0 - 1, j0)
    j0 = torch.where(j0.to(lo.dtype) + 0.5 < lo, j0 + 1, j0)
    j1 = torch.floor(hi - 0.5).to(torch.int64)
    j1 = torch.where((j1 + 1).to(hi.dtype) + 0.5 <= hi, j1 + 1, j1)
    j1 = torch.where(j1.to(hi.dtype) + 0.5 > hi, j1 - 1, j1)
    return j0.clamp(min=0), j1.clamp(max=n - 1)


def _alpha_from_offsets(d, conic, opacity):
    """VG-ALPHA from offsets d = pixel - mean2d (..., 2): alpha (...), 0 where skipped."""
    return _alpha(d[..., 0], d[..., 1], conic[..., 0], conic[..., 1], conic[..., 2], opacity)


def _alpha(du, dv, a, b, c, o):
    sigma = 0.5 * (a * du * du + c * dv * dv) + b * du * dv
    # exp(-sigma) overflows for a very negative sigma and 0 * inf = NaN in backward even
    # though such pairs are skipped: evaluate it at max(sigma, 0).
    alpha = torch.clamp(o * torch.exp(-torch.clamp(sigma, min=0)), max=ALPHA_MAX)
    return torch.where((sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))


def _pixel_centres(width, height, dtype, device):
    """Pixel-centre coordinates (u, v) of every flat pixel index: two (P,) tensors."""
    j = torch.arange(width, dtype=dtype, device=device) + 0.5
    i = torch.arange(height, dtype=dtype, device=device) + 0.5
    return j.repeat(height), i.repeat_interleave(width)


def _chunks(offsets, size):
    """Split the pair table into (p0, p1, a, b): pixels p0:p1 own pairs a:b, b - a ~ size."""
    m, n_pix = int(offsets[-1]), len(offsets) - 1
    if m == 0:
        return []
    targets = offsets.new_tensor(list(range(size, m, size)))
    cuts = torch.searchsorted(offsets, targets).tolist()
    bounds = sorted(set([0, n_pix] + [min(p, n_pix) for p in cuts]))
    return [(p0, p1, int(offsets[p0]), int(offsets[p1])) for p0, p1 in zip(bounds[:-1], bounds[1:])
            if offsets[p1] > offsets[p0]]


def _pair_alpha(cols, centres, gid, pix):
    """VG-ALPHA of pairs: cols are the per-Gaussian columns (u, v, a, b, c, o, ...)."""
    u, v, a, b, c, o = (t.index_select(0, gid) for t in cols[:6])
    du = centres[0].index_select(0, pix) - u
    dv = centres[1].index_select(0, pix) - v
    return _alpha(du, dv, a, b, c, o)


def _transmittance(alpha, counts):
    """Front-to-back transmittance of pairs grouped in consecutive runs of `counts` (pixels).

    alpha: (m,) pair opacities (0 = skipped), pixel after pixel, in depth order within a
    pixel; counts: (p,) pairs per pixel, summing to m. Returns (T, blended, logt): T (m,)
    the transmittance before each pair (working dtype), the VG-BLEND mask of the pairs
    actually blended and log(1 - alpha). log T is a float64 prefix sum of log(1 - alpha)
    within the pixel.
    """
    logt = torch.log1p(-alpha)  # exactly 0 for skipped pairs
    l_excl, _, _ = _pixel_prefix(logt, counts[counts > 0])
    blended = (alpha > 0) & (l_excl + logt >= _LOG_TRANSMITTANCE_MIN)
    return torch.exp(l_excl).to(alpha.dtype), blended, logt


def _pixel_prefix(x, cnt):
    """Float64 sums of x (m,) within consecutive runs of cnt (p,) > 0 elements (pixels).

    Returns (excl, total, owner): excl (m,) the sum of the run's earlier elements, total
    (p,) each run's sum, owner (m,) the run of each element. One cumulative sum serves all
    runs: each run's last element also takes away the run's total, so the running sum
    restarts near 0 at every run and its rounding is that of one run's own sums, however
    long the table (instead of 1e-16 times the whole chunk's sum).
    """
    first = torch.cumsum(cnt, 0) - cnt
    owner = torch.repeat_interleave(torch.arange(len(cnt), device=x.device), cnt, output_size=len(x))
    x = x.to(torch.float64)
    total = torch.zeros(len(cnt), dtype=torch.float64, device=x.device).index_add_(0, owner, x)
    y = x.index_add(0, first + cnt - 1, total, alpha=-1)
    excl = torch.cumsum(y, 0) - y
    return excl - excl.index_select(0, first).index_select(0, owner), total, owner


def _gaussian_columns(mean2d, conic, opacity, rgb):
    """Per-Gaussian inputs as 9 contiguous (N,) columns: u, v, a, b, c, o, r, g, b.

    Gathering 1-D columns is several times faster on CPU than gathering rows of (N, 9).
    """
    return torch.cat([mean2d, conic, opacity[:, None], rgb], dim=1).T.contiguous()


class _Composite(torch.autograd.Function):
    """Per-pixel front-to-back compositing of the sorted pair table, analytic backward.

    Inputs mean2d (N, 2), conic (N, 3), opacity (N,), rgb (N, 3), background (3,), pairs;
    outputs image (P, 3) and final transmittance T (P,). Saves for backward the pair table
    and two numbers per pair, alpha of the blended pairs (0 otherwise) and T, so memory is
    the table plus one chunk of temporaries; the backward is the 3DGS one with the
    geometric part reduced to per-Gaussian moments of d sigma.
    """

    @staticmethod
    def forward(ctx, mean2d, conic, opacity, rgb, background, pairs):
        cols = _gaussian_columns(mean2d, conic, opacity, rgb)
        dtype, device = cols.dtype, cols.device
        n_pix, m = pairs.width * pairs.height, len(pairs.gid)
        centres = _pixel_centres(pairs.width, pairs.height, dtype, device)
        counts = pairs.offsets[1:] - pairs.offsets[:-1]
        image = torch.zeros(3, n_pix, dtype=dtype, device=device)
        log_t = torch.zeros(n_pix, dtype=torch.float64, device=device)
        alpha_all = torch.empty(m, dtype=dtype, device=device)
        T_all = torch.empty(m, dtype=dtype, device=device)
        for p0, p1, a, b in _chunks(pairs.offsets, _CHUNK_PAIRS):
            gid, pix = pairs.gid[a:b], pairs.pix[a:b]
            alpha = _pair_alpha(cols, centres, gid, pix)
            T, blended, logt = _transmittance(alpha, counts[p0:p1])
            alpha = torch.where(blended, alpha, torch.zeros_like(alpha))
            log_t.index_add_(0, pix, torch.where(blended, logt, torch.zeros_like(logt)).to(torch.float64))
            w = alpha * T
            for k in range(3):
                image[k].index_add_(0, pix, w * cols[6 + k].index_select(0, gid))
            alpha_all[a:b], T_all[a:b] = alpha, T
        T_final = torch.exp(log_t).to(dtype)
        image = (image.T + T_final[:, None] * background).contiguous()
        ctx.save_for_backward(cols, background, T_final, pairs.gid, pairs.pix, pairs.offsets, alpha_all, T_all)
        ctx.size = (pairs.width, pairs.height)
        return image, T_final

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_image, g_T):
        cols, background, T_final, gid_all, pix_all, offsets, alpha_all, T_all = ctx.saved_tensors
        dtype, device = cols.dtype, cols.device
        centres = _pixel_centres(*ctx.size, dtype, device)
        counts = offsets[1:] - offsets[:-1]
        g_image = g_image.T.contiguous()  # [3, P]
        # image = ... + T_final * background: the background term joins dL/dT_final.
        g_tf = g_T + (g_image * background[:, None]).sum(0)
        g_background = (g_image * T_final).sum(1)
        # Every pair's (1 - alpha) factor scales T_final: the part of d(pixel)/d(alpha_i)
        # that all pairs of a pixel share.
        tail = T_final * g_tf
        n = cols.shape[1]
        # Per Gaussian: sum of w gI (3), and moments of g_sigma = dL/dsigma over its pairs:
        # sum g_sigma, sum g_sigma du, dv, du^2, du dv, dv^2 (du, dv centred on the mean,
        # so the sums do not cancel).
        g_rgb = torch.zeros(3, n, dtype=dtype, device=device)
        mom = torch.zeros(6, n, dtype=dtype, device=device)
        for p0, p1, a, b in _chunks(offsets, _CHUNK_PAIRS):
            gid, pix = gid_all[a:b], pix_all[a:b]
            alpha, T = alpha_all[a:b], T_all[a:b]
            cnt = counts[p0:p1]
            live = cnt > 0
            gi = [g_image[k].index_select(0, pix) for k in range(3)]
            w = alpha * T
            cg = gi[0] * cols[6].index_select(0, gid)
            cg.addcmul_(gi[1], cols[7].index_select(0, gid)).addcmul_(gi[2], cols[8].index_select(0, gid))
            for k in range(3):
                g_rgb[k].index_add_(0, gid, w * gi[k])
            # Loss-weighted colour of everything behind pair i in its pixel, plus the
            # background/T_final term, from float64 sums within the pixel.
            wcg = w * cg
            excl, total, owner = _pixel_prefix(wcg, cnt[live])
            behind = (total.index_select(0, owner) - excl - wcg).to(dtype) + tail[p0:p1][live].index_select(0, owner)
            g_alpha = T * cg - behind / (1 - alpha)
            # d alpha / d sigma = -alpha unless skipped, terminated or clamped at ALPHA_MAX.
            g_sigma = torch.where((alpha > 0) & (alpha < ALPHA_MAX), g_alpha * -alpha, torch.zeros_like(alpha))
            du = centres[0].index_select(0, pix) - cols[0].index_select(0, gid)
            dv = centres[1].index_select(0, pix) - cols[1].index_select(0, gid)
            gdu, gdv = g_sigma * du, g_sigma * dv
            for k, t in enumerate((g_sigma, gdu, gdv, gdu * du, gdu * dv, gdv * dv)):
                mom[k].index_add_(0, gid, t)
        s0, s_u, s_v, s_uu, s_uv, s_vv = mom
        ca, cb, cc, o = cols[2], cols[3], cols[4], cols[5]
        # sigma = (a du^2 + c dv^2) / 2 + b du dv with du = px - u: d sigma/du = -(a du + b dv).
        g_mean2d = torch.stack([-(ca * s_u + cb * s_v), -(cb * s_u + cc * s_v)], dim=1)
        g_conic = torch.stack([0.5 * s_uu, s_uv, 0.5 * s_vv], dim=1)
        # alpha = o exp(-sigma) where unclamped, so d alpha/d o = alpha / o and
        # sum g_alpha alpha / o = -s0 / o; a Gaussian with o = 0 has no unclamped pair.
        g_opacity = torch.where(o > 0, -s0 / torch.where(o > 0, o, torch.ones_like(o)), torch.zeros_like(o))
        return g_mean2d, g_conic, g_opacity, g_rgb.T, g_background, None


def _composite_autograd(mean2d, conic, opacity, rgb, background, pairs):
    """`_Composite` left to autograd: same inputs, outputs and formulation, no chunks.

    Keeps every per-pair intermediate alive until backward; used by tests as the
    independent gradient of the analytic backward, and by the benchmark.
    """
    cols = _gaussian_columns(mean2d, conic, opacity, rgb)
    n_pix = pairs.width * pairs.height
    centres = _pixel_centres(pairs.width, pairs.height, cols.dtype, cols.device)
    counts = pairs.offsets[1:] - pairs.offsets[:-1]
    alpha = _pair_alpha(cols, centres, pairs.gid, pairs.pix)
    T, blended, logt = _transmittance(alpha, counts)
    alpha = torch.where(blended, alpha, torch.zeros_like(alpha))
    w = alpha * T
    image = torch.stack(
        [cols.new_zeros(n_pix).index_add(0, pairs.pix, w * cols[6 + k].index_select(0, pairs.gid)) for k in range(3)],
        dim=1,
    )
    logt = torch.where(blended, logt, torch.zeros_like(logt)).to(torch.float64)
    log_t = torch.zeros(n_pix, dtype=torch.float64, device=cols.device).index_add(0, pairs.pix, logt)
    T_final = torch.exp(log_t).to(cols.dtype)
    return image + T_final[:, None] * background, T_final


# The compositing of each torch-side backend of `rasterize`.
COMPOSITES = {"torch": _composite_torch, "numba": _composite_numba}
