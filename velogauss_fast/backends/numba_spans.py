"""The numba backend's row spans: `velogauss_fast.spans.row_spans` in one compiled loop.

The torch form computes the spans of a view's Gaussians in about seventy small tensor
operations; here each valid Gaussian is one pass of scalar code with the same operations in
the same dtypes: the box in the working dtype (so its pixel membership is the reference's,
bit for bit), the span parameters in float64. The depth order is the same function
(`spans.depth_order`). The logarithm of the pruning bound may differ from torch's in its
last bit; the bound's margin (SPAN_SIGMA_SLACK and more) is far above that, so the pairs the
compositing blends are the same.
"""

import math

import numba
import numpy as np
import torch

from velogauss_core.constants import ALPHA_MIN, SPAN_SIGMA_SLACK
from velogauss_fast.spans import SPAN_COLUMNS, Spans, depth_order, row_spans

# As numba_kernels: no Python division checks, IEEE rounding (no fastmath), cached on disk,
# the GIL released.
_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def _centre_span(lo, hi, n, half, scratch):
    """`spans._centre_span` of one interval [lo, hi] given in the working dtype; half: 0.5 in
    it; scratch: a 1-element array of it, through which integers are cast to it (as
    `.to(dtype)` does), so that j + 0.5 is computed and compared as the torch form does. The
    clamp's bounds are integers, exact in any float type: clamping in float64 changes nothing."""
    lo = min(max(lo, -1.0), n + 1.0)
    hi = min(max(hi, -1.0), n + 1.0)
    j0 = np.int64(np.ceil(lo - half))
    scratch[0] = j0 - 1
    if scratch[0] + half >= lo:
        j0 -= 1
    scratch[0] = j0
    if scratch[0] + half < lo:
        j0 += 1
    j1 = np.int64(np.floor(hi - half))
    scratch[0] = j1 + 1
    if scratch[0] + half <= hi:
        j1 += 1
    scratch[0] = j1
    if scratch[0] + half > hi:
        j1 -= 1
    return max(j0, 0), min(j1, n - 1)


@numba.njit(**_JIT)
def spans_forward(ids, mean2d, conic, opacity, radius, width, height, eps, half, geom):
    """Fill geom (n, 15) (`spans.SPAN_COLUMNS`) for the Gaussians `ids` (n,) in depth order;
    returns n_box. mean2d (N, 2), conic (N, 3), opacity (N,), radius (N,) in the working
    dtype; eps: its machine epsilon; half: 0.5 in it."""
    scratch = np.empty(1, dtype=mean2d.dtype)
    n_box = 0
    for k in range(ids.shape[0]):
        g = ids[k]
        u, v, r = mean2d[g, 0], mean2d[g, 1], radius[g]
        x0, x1 = _centre_span(u - r, u + r, width, half, scratch)
        y0, y1 = _centre_span(v - r, v + r, height, half, scratch)
        n_box += max(x1 - x0 + 1, 0) * max(y1 - y0 + 1, 0)
        u, v, r = np.float64(u), np.float64(v), np.float64(r)
        a, b, c, o = np.float64(conic[g, 0]), np.float64(conic[g, 1]), np.float64(conic[g, 2]), np.float64(opacity[g])
        margin = SPAN_SIGMA_SLACK + 8 * eps * (abs(a) + abs(c) + 2 * abs(b)) * ((r + 1) * (r + 1))
        s = math.log(o / ALPHA_MIN) + margin
        det = a * c - b * b
        definite = a > 0 and det > 0
        a_safe = a if definite else 1.0
        row = geom[k]
        row[0], row[1], row[2], row[3], row[4], row[5] = u, v, a, b, c, o
        row[6], row[7], row[8], row[9] = 2 * a * s, det, 1 / a_safe, b / a_safe
        row[10] = 1.0 if definite else 0.0
        row[11], row[12], row[13], row[14] = x0, x1, y0, y1
    return n_box


def row_spans_numba(mean2d, conic, opacity, radius, depth, valid, width, height):
    """`velogauss_fast.spans.row_spans` (same arguments, same Spans) in the kernel: CPU tensors.
    A half-precision working dtype (float16, bfloat16), which numba does not compile, takes
    the torch form."""
    if mean2d.dtype not in (torch.float32, torch.float64):
        return row_spans(mean2d, conic, opacity, radius, depth, valid, width, height)
    with torch.no_grad():
        ids = depth_order(depth, valid)
        m, c, o = (t.detach().contiguous().numpy() for t in (mean2d, conic, opacity))
        geom = np.empty((ids.shape[0], len(SPAN_COLUMNS)))
        n_box = spans_forward(ids.numpy(), m, c, o, radius.to(mean2d.dtype).numpy(), width, height,
                              float(np.finfo(m.dtype).eps), m.dtype.type(0.5), geom)
    return Spans(ids, torch.from_numpy(geom), width, height, int(n_box))
