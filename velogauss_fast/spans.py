"""The row spans and the pair table of the torch rasterizer (spec/rendering.md, VG-RENDER).

`row_spans` gives, per valid Gaussian in depth order, each box row's interval inside its
alpha >= ALPHA_MIN ellipse (what the numba backend walks); `pair_table` lists those
(Gaussian, pixel) pairs sorted by (pixel, depth) (what the torch backend composites,
`velogauss_fast.composite`). Both trust their caller, `velogauss_fast.raster.rasterize`.
"""

from typing import NamedTuple

import torch

from velogauss_core.constants import ALPHA_MIN, SPAN_SIGMA_SLACK


class Spans(NamedTuple):
    """Per valid Gaussian, in depth order, what is needed to list and composite its pairs row by row."""

    ids: torch.Tensor  # [n] int64 Gaussian index, sorted by (depth, index)
    geom: torch.Tensor  # [n, 15] float64: the SPAN_COLUMNS below
    width: int
    height: int
    n_box: int  # (valid Gaussian, pixel) pairs whose box holds the centre, pruned or not


# Columns of Spans.geom: the mean, conic and opacity, then the row spans: sigma <= s  <=>
# a du^2 + 2 b dv du + c dv^2 <= 2 s, so the row at offset dv from the mean keeps du in
# centre +- half with centre = u - (b / a) dv and half = sqrt(2 a s - det dv^2) / a
# (det = a c - b^2); "definite" is 0 for a conic that is not numerically positive definite
# (its rows keep the whole box); x0..y1 the box.
SPAN_COLUMNS = ("u", "v", "a", "b", "c", "opacity", "two_as", "det", "inv_a", "b_over_a", "definite",
                "x0", "x1", "y0", "y1")
# Integer views whose order is that of positive floats of the same width.
_BITS = {torch.float16: torch.int16, torch.bfloat16: torch.int16, torch.float32: torch.int32,
         torch.float64: torch.int64}


def row_spans(mean2d, conic, opacity, radius, depth, valid, width, height):
    """The row-span parameters of every valid Gaussian, in depth order (see `Spans`).

    A pair of VG-RENDER is a valid Gaussian and a pixel centre inside its box. Pairs with
    alpha < ALPHA_MIN are skipped by VG-ALPHA and change nothing (not even T), so only the
    pixels of each box row where sigma <= log(opacity / ALPHA_MIN) + margin are listed:
    an interval of the row (the conic's ellipse), computed per (Gaussian, row) in float64
    by `pair_table` here and by the numba kernels' `row_span`, with the same operations.
    The margin (`_span_margin`) exceeds the rounding of sigma in the working dtype, so
    every dropped pair has a computed alpha < ALPHA_MIN; kept pairs may still be skipped.
    Ties in depth keep index order (stable sort).
    """
    with torch.no_grad():
        f64 = torch.float64
        ids = depth_order(depth, valid)
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
    return Spans(ids, geom, width, height, n_box)


def depth_order(depth, valid):
    """Indices (n,) int64 of the valid Gaussians (valid (N,) bool) by increasing depth (N,),
    ties in index order: the order VG-RENDER composites them in."""
    with torch.no_grad():
        ids = torch.nonzero(valid).squeeze(1)
        # Valid depths are >= NEAR_PLANE > 0, and positive floats order as their bit
        # patterns: a stable (radix) sort of the integer view is the stable depth order,
        # ~10x faster on the CPU than sorting the floats.
        d = depth.index_select(0, ids)
        return ids.index_select(0, torch.sort(d.view(_BITS[d.dtype]), stable=True).indices)


class Pairs(NamedTuple):
    """(Gaussian, pixel) pairs sorted by (pixel, depth, index); pixel = row * width + col."""

    gid: torch.Tensor  # [M] int64 Gaussian index
    pix: torch.Tensor  # [M] int64 flat pixel index, non-decreasing
    offsets: torch.Tensor  # [P + 1] int64: the pairs of pixel p are offsets[p]:offsets[p+1]
    width: int
    height: int
    n_box: int  # as in Spans


def pair_table(spans):
    """The (Gaussian, pixel) pairs of `spans` (see `row_spans`), sorted by (pixel, depth).

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
    return Pairs(gid, pix, offsets, spans.width, spans.height, spans.n_box)


def _span_margin(a, b, c, r, dtype):
    """Slack on sigma covering its rounding in `dtype`: sigma sums terms up to
    (a + c + 2|b|)(r + 1)^2 / 2 (offsets up to the box radius), each rounded to a few eps."""
    eps = torch.finfo(dtype).eps
    return SPAN_SIGMA_SLACK + 8 * eps * (a.abs() + c.abs() + 2 * b.abs()) * (r + 1) ** 2


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
