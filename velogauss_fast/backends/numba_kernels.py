"""Compiled CPU kernels of the numba backend (VG-ALPHA, VG-BLEND, VG-RENDER), scalar float64.

Compositing is Gaussian-major: the kernels visit the Gaussians in depth order and, for
each, the pixels of its rows' spans, keeping a running state per pixel. Every pixel thus
meets its pairs in the order VG-RENDER prescribes (depth, then index) with no pair table
and no sort, and the early stop of VG-BLEND is a per-pixel flag. The backward visits the
Gaussians in reverse depth order: the 3DGS backward, with the transmittance before each
pair recovered as T_i = T_{i+1} / (1 - alpha_i) (1 - alpha_i >= 1 - ALPHA_MAX, so each
division adds one rounding, ~1e-16 relative in float64) and the loss-weighted colour of
everything behind it carried per pixel.

Work is split across threads by image rows: part k of n owns the rows r with r % n == k,
so parts write disjoint pixels and interleaved rows balance the load. Each part writes its
own per-Gaussian gradient rows; the caller sums the parts in a fixed order, so results do
not depend on scheduling.

Row `rank` of `prm` (float64, (n, N_COLUMNS)) describes the Gaussian of depth rank
`rank`, columns as named below. Row spans follow velogauss_fast.spans.row_spans: the
same float64 operations in the same order, so both backends visit the same pairs.
"""

import math

import numba

from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN

# Columns of `prm`: velogauss_fast.spans.SPAN_COLUMNS (mean, conic, opacity, row spans),
# then the colour.
U, V, CA, CB, CC, OPACITY, TWO_AS, DET, INV_A, B_OVER_A, DEFINITE, X0, X1, Y0, Y1 = range(15)
RED, GREEN, BLUE = range(15, 18)
N_COLUMNS = 18
# Columns of the per-Gaussian gradient rows: dL/d (u, v, a, b, c, opacity, r, g, b), from
# the sums over the Gaussian's pairs of g_sigma = dL/dsigma times 1, du, dv, du^2, du dv,
# dv^2 (linear in them, so each part's rows can be summed afterwards).
G_U, G_V, G_A, G_B, G_C, G_O, G_RED, G_GREEN, G_BLUE = range(9)
N_GRAD = 9
# Pixels between exact exps in the forward's recurrence for o exp(-sigma) along a row.
EXP_RESTART = 16

# error_model="numpy": no Python ZeroDivisionError checks in the loops (no division can
# be by zero: 1 - alpha >= 1 - ALPHA_MAX); fastmath stays off so every operation rounds as
# IEEE float64, like the torch backend and the reference.
_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def row_span(prm, rank, row, width):
    """Columns [xa, xb] of box row `row` where Gaussian `rank` can have alpha >= ALPHA_MIN, and
    whether they come from the ellipse (False: the whole box row of an indefinite conic)."""
    x0, x1 = int(prm[rank, X0]), int(prm[rank, X1])
    if prm[rank, DEFINITE] == 0.0:
        return x0, x1, False
    dv = row + 0.5 - prm[rank, V]
    disc = prm[rank, TWO_AS] - prm[rank, DET] * dv * dv
    if disc < 0:
        return x0, x0 - 1, True
    half = math.sqrt(disc) * prm[rank, INV_A]
    centre = prm[rank, U] - prm[rank, B_OVER_A] * dv
    lo = math.ceil(centre - half - 0.5)
    hi = math.floor(centre + half - 0.5)
    if not (lo == lo and hi == hi):  # NaN from an extreme conic: keep the whole box row
        return x0, x1, False
    lo = min(max(lo, -1.0), width + 1.0)
    hi = min(max(hi, -1.0), width + 1.0)
    return max(int(lo), x0), min(int(hi), x1), True


@numba.njit(**_JIT)
def pair_alpha(a, b, c, o, du, dv):
    """VG-ALPHA of conic (a, b, c) and opacity o at offset (du, dv) from the mean: alpha, 0 where skipped."""
    sigma = 0.5 * (a * du * du + c * dv * dv) + b * du * dv
    if sigma < 0:
        return 0.0
    alpha = min(o * math.exp(-sigma), ALPHA_MAX)
    return alpha if alpha >= ALPHA_MIN else 0.0


@numba.njit(**_JIT)
def count_pairs(n_parts, prm, width, counts):
    """Pairs in the rows of each part, into counts (n_parts,): the lengths of their alpha
    buffers. One pass for all parts: the pass is light, and threads measured slower."""
    for rank in range(prm.shape[0]):
        for row in range(int(prm[rank, Y0]), int(prm[rank, Y1]) + 1):
            xa, xb, _ = row_span(prm, rank, row, width)
            counts[row % n_parts] += max(xb - xa + 1, 0)


@numba.njit(**_JIT)
def composite_forward(part, n_parts, prm, width, color, trans, last, done, alphas):
    """Front-to-back compositing of the rows owned by `part` (VG-BLEND over VG-RENDER's pairs).

    color (P, 3), trans (P,) (start 1), last (P,) int (start -1), done (P,) uint8 (start 0)
    are updated in place: blended colour, final T, rank of the last blended Gaussian and
    the early-stop flag. alphas (the part's count,) receives the alpha of every pair in
    visiting order (0 where skipped or after the pixel's stop), for the backward.

    Along an ellipse row, o exp(-sigma) is advanced by two products per pixel instead of
    one exp: sigma(du + 1) - sigma(du) = a du + a / 2 + b dv grows by a per pixel, so
    e <- e r, r <- r exp(-a). The factors stay finite (|a du + b dv| <= sqrt(2 a s) + a
    inside the span, a few tens at most) and the recurrence restarts from exact exps every
    EXP_RESTART pixels, which bounds its rounding to ~EXP_RESTART^2 / 4 ulp (1e-14
    relative in float64). sigma itself is computed directly, for the sigma < 0 skip.
    """
    k = 0
    for rank in range(prm.shape[0]):
        y0, y1 = int(prm[rank, Y0]), int(prm[rank, Y1])
        u, v, a, b, c, o = prm[rank, U], prm[rank, V], prm[rank, CA], prm[rank, CB], prm[rank, CC], prm[rank, OPACITY]
        red, green, blue = prm[rank, RED], prm[rank, GREEN], prm[rank, BLUE]
        q = math.exp(-a)
        for row in range(y0 + (part - y0) % n_parts, y1 + 1, n_parts):
            xa, xb, ellipse = row_span(prm, rank, row, width)
            dv = row + 0.5 - v
            e = step = 0.0
            for x in range(xa, xb + 1):
                p = row * width + x
                du = x + 0.5 - u
                if not ellipse:
                    alpha = pair_alpha(a, b, c, o, du, dv)
                else:
                    sigma = 0.5 * (a * du * du + c * dv * dv) + b * du * dv
                    if (x - xa) % EXP_RESTART == 0:
                        e = o * math.exp(-sigma)
                        step = math.exp(-(a * du + 0.5 * a + b * dv))
                    alpha = min(e, ALPHA_MAX)
                    if sigma < 0 or alpha < ALPHA_MIN:
                        alpha = 0.0
                    e *= step
                    step *= q
                if done[p]:
                    alpha = 0.0
                alphas[k] = alpha
                k += 1
                if alpha == 0.0:
                    continue
                t_next = trans[p] * (1.0 - alpha)
                if t_next < TRANSMITTANCE_MIN:
                    done[p] = 1
                    continue
                w = alpha * trans[p]
                color[p, 0] += w * red
                color[p, 1] += w * green
                color[p, 2] += w * blue
                trans[p] = t_next
                last[p] = rank


@numba.njit(**_JIT)
def composite_backward(part, n_parts, prm, width, g_image, trans, behind, last, alphas, grads):
    """Back-to-front gradients of the rows owned by `part`: the forward's visits reversed.

    g_image (P, 3) dL/d colour; trans (P,) starts at the final T and behind (P,) at
    T_final * dL/dT_final (the background's share included); both are updated in place.
    alphas: the forward's buffer of this part. grads (n, N_GRAD): this part's
    per-Gaussian rows, written (not accumulated).
    """
    k = alphas.shape[0]
    for rank in range(prm.shape[0] - 1, -1, -1):
        y0, y1 = int(prm[rank, Y0]), int(prm[rank, Y1])
        u, v = prm[rank, U], prm[rank, V]
        red, green, blue = prm[rank, RED], prm[rank, GREEN], prm[rank, BLUE]
        g_r = g_g = g_b = s0 = s_u = s_v = s_uu = s_uv = s_vv = 0.0
        first = y0 + (part - y0) % n_parts
        for row in range(first + (y1 - first) // n_parts * n_parts, first - 1, -n_parts):
            xa, xb, _ = row_span(prm, rank, row, width)
            dv = row + 0.5 - v
            for x in range(xb, xa - 1, -1):
                k -= 1
                alpha = alphas[k]
                p = row * width + x
                # Skipped, or after the pixel's last blended pair (or its stop).
                if alpha == 0.0 or rank > last[p]:
                    continue
                inv_keep = 1.0 / (1.0 - alpha)
                T = trans[p] * inv_keep
                w = alpha * T
                gi0, gi1, gi2 = g_image[p, 0], g_image[p, 1], g_image[p, 2]
                cg = gi0 * red + gi1 * green + gi2 * blue
                g_r += w * gi0
                g_g += w * gi1
                g_b += w * gi2
                g_alpha = T * cg - behind[p] * inv_keep
                behind[p] += w * cg
                trans[p] = T
                # d alpha / d sigma = -alpha unless clamped at ALPHA_MAX.
                if alpha < ALPHA_MAX:
                    du = x + 0.5 - u
                    g_sigma = -alpha * g_alpha
                    s0 += g_sigma
                    s_u += g_sigma * du
                    s_v += g_sigma * dv
                    s_uu += g_sigma * du * du
                    s_uv += g_sigma * du * dv
                    s_vv += g_sigma * dv * dv
        # sigma = (a du^2 + c dv^2) / 2 + b du dv with du = px - u: d sigma/du = -(a du + b dv).
        a, b, c, o = prm[rank, CA], prm[rank, CB], prm[rank, CC], prm[rank, OPACITY]
        grads[rank, G_U] = -(a * s_u + b * s_v)
        grads[rank, G_V] = -(b * s_u + c * s_v)
        grads[rank, G_A], grads[rank, G_B], grads[rank, G_C] = 0.5 * s_uu, s_uv, 0.5 * s_vv
        # alpha = o exp(-sigma) where unclamped, so sum g_alpha d alpha/d o = -s0 / o; a
        # Gaussian with o = 0 has no unclamped pair.
        grads[rank, G_O] = -s0 / o if o > 0 else 0.0
        grads[rank, G_RED], grads[rank, G_GREEN], grads[rank, G_BLUE] = g_r, g_g, g_b
