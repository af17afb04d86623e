"""Compositing of the sorted pair table with an analytic backward, in torch (VG-ALPHA, VG-BLEND).

The torch backend of `velogauss_fast.raster.rasterize` (see its module docstring for the
formulation): every pixel's run of the pair table (`velogauss_fast.spans.pair_table`) is
composited at once, chunk by chunk, with float64 prefix sums of log(1 - alpha) for the
transmittance and exact early termination. `Composite` is the autograd Function with the
3DGS backward; `composite_autograd` the same formulation left to autograd (tests compare
the two, the benchmark times both). Inputs are trusted: `rasterize` checks them.
"""

import math

import torch

from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN

# Pairs composited per chunk: bounds the temporaries of forward and backward (about 100
# bytes per pair) to ~25 MB while keeping the per-chunk Python overhead negligible. Measured
# on W3 (velogauss.bench.raster, 2 threads): 1<<18 took 0.33 s and 180 MiB forward+backward,
# 1<<20 0.37 s and 219 MiB, 1<<16 0.44 s (the loop overhead starts to show).
CHUNK_PAIRS = 1 << 18
_LOG_TRANSMITTANCE_MIN = math.log(TRANSMITTANCE_MIN)


def alpha_from_offsets(d, conic, opacity):
    """VG-ALPHA from offsets d = pixel - mean2d (..., 2): alpha (...), 0 where skipped."""
    return _alpha(d[..., 0], d[..., 1], conic[..., 0], conic[..., 1], conic[..., 2], opacity)


def _alpha(du, dv, a, b, c, o):
    sigma = 0.5 * (a * du * du + c * dv * dv) + b * du * dv
    # exp(-sigma) overflows for a very negative sigma and 0 * inf = NaN in backward even
    # though such pairs are skipped: evaluate it at max(sigma, 0).
    alpha = torch.clamp(o * torch.exp(-torch.clamp(sigma, min=0)), max=ALPHA_MAX)
    return torch.where((sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))


def pixel_centres(width, height, dtype, device):
    """Pixel-centre coordinates (u, v) of every flat pixel index: two (P,) tensors."""
    j = torch.arange(width, dtype=dtype, device=device) + 0.5
    i = torch.arange(height, dtype=dtype, device=device) + 0.5
    return j.repeat(height), i.repeat_interleave(width)


def chunks(offsets, size):
    """Split the pair table into (p0, p1, a, b): pixels p0:p1 own pairs a:b, b - a ~ size."""
    m, n_pix = int(offsets[-1]), len(offsets) - 1
    if m == 0:
        return []
    targets = offsets.new_tensor(list(range(size, m, size)))
    cuts = torch.searchsorted(offsets, targets).tolist()
    bounds = sorted(set([0, n_pix] + [min(p, n_pix) for p in cuts]))
    return [(p0, p1, int(offsets[p0]), int(offsets[p1])) for p0, p1 in zip(bounds[:-1], bounds[1:])
            if offsets[p1] > offsets[p0]]


def pair_alpha(cols, centres, gid, pix):
    """VG-ALPHA of pairs: cols are the per-Gaussian columns (u, v, a, b, c, o, ...)."""
    u, v, a, b, c, o = (t.index_select(0, gid) for t in cols[:6])
    du = centres[0].index_select(0, pix) - u
    dv = centres[1].index_select(0, pix) - v
    return _alpha(du, dv, a, b, c, o)


def transmittance(alpha, counts):
    """Front-to-back transmittance of pairs grouped in consecutive runs of `counts` (pixels).

    alpha: (m,) pair opacities (0 = skipped), pixel after pixel, in depth order within a
    pixel; counts: (p,) pairs per pixel, summing to m. Returns (T, blended, logt): T (m,)
    the transmittance before each pair (working dtype), the VG-BLEND mask of the pairs
    actually blended and log(1 - alpha). log T is a float64 prefix sum of log(1 - alpha)
    within the pixel.
    """
    logt = torch.log1p(-alpha)  # exactly 0 for skipped pairs
    l_excl, _, _ = pixel_prefix(logt, counts[counts > 0])
    blended = (alpha > 0) & (l_excl + logt >= _LOG_TRANSMITTANCE_MIN)
    return torch.exp(l_excl).to(alpha.dtype), blended, logt


def pixel_prefix(x, cnt):
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


def gaussian_columns(mean2d, conic, opacity, rgb):
    """Per-Gaussian inputs as 9 contiguous (N,) columns: u, v, a, b, c, o, r, g, b.

    Gathering 1-D columns is several times faster on CPU than gathering rows of (N, 9).
    """
    return torch.cat([mean2d, conic, opacity[:, None], rgb], dim=1).T.contiguous()


class Composite(torch.autograd.Function):
    """Per-pixel front-to-back compositing of the sorted pair table, analytic backward.

    Inputs mean2d (N, 2), conic (N, 3), opacity (N,), rgb (N, 3), background (3,), pairs;
    outputs image (P, 3) and final transmittance T (P,). Saves for backward the pair table
    and two numbers per pair, alpha of the blended pairs (0 otherwise) and T, so memory is
    the table plus one chunk of temporaries; the backward is the 3DGS one with the
    geometric part reduced to per-Gaussian moments of d sigma.
    """

    @staticmethod
    def forward(ctx, mean2d, conic, opacity, rgb, background, pairs):
        cols = gaussian_columns(mean2d, conic, opacity, rgb)
        dtype, device = cols.dtype, cols.device
        n_pix, m = pairs.width * pairs.height, len(pairs.gid)
        centres = pixel_centres(pairs.width, pairs.height, dtype, device)
        counts = pairs.offsets[1:] - pairs.offsets[:-1]
        image = torch.zeros(3, n_pix, dtype=dtype, device=device)
        log_t = torch.zeros(n_pix, dtype=torch.float64, device=device)
        alpha_all = torch.empty(m, dtype=dtype, device=device)
        T_all = torch.empty(m, dtype=dtype, device=device)
        for p0, p1, a, b in chunks(pairs.offsets, CHUNK_PAIRS):
            gid, pix = pairs.gid[a:b], pairs.pix[a:b]
            alpha = pair_alpha(cols, centres, gid, pix)
            T, blended, logt = transmittance(alpha, counts[p0:p1])
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
        centres = pixel_centres(*ctx.size, dtype, device)
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
        for p0, p1, a, b in chunks(offsets, CHUNK_PAIRS):
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
            excl, total, owner = pixel_prefix(wcg, cnt[live])
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


def composite_autograd(mean2d, conic, opacity, rgb, background, pairs):
    """`Composite` left to autograd: same inputs, outputs and formulation, no chunks.

    Keeps every per-pair intermediate alive until backward; used by tests as the
    independent gradient of the analytic backward, and by the benchmark.
    """
    cols = gaussian_columns(mean2d, conic, opacity, rgb)
    n_pix = pairs.width * pairs.height
    centres = pixel_centres(pairs.width, pairs.height, cols.dtype, cols.device)
    counts = pairs.offsets[1:] - pairs.offsets[:-1]
    alpha = pair_alpha(cols, centres, pairs.gid, pairs.pix)
    T, blended, logt = transmittance(alpha, counts)
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
