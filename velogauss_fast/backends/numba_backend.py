"""Compiled CPU compositing for `velogauss_fast.raster.rasterize` (backend="numba").

Each view's projection, covariance, colours and culling run in `numba_projection`, its
row spans in `numba_spans` (the torch backend's, compiled), and the compositing of
VG-RENDER's pairs in the kernels of `numba_kernels`, forward and an analytic backward. No
pair table is built: backward revisits the pairs through the same row spans and saves, per pixel, the final T and the rank of the last blended
Gaussian and, per pair, its alpha (one float64 in visiting order, so the backward needs no
exp). The kernels compute in float64 whatever the working dtype (inputs are cast up,
outputs cast back), so a float32 render differs from the reference only by its float32
inputs.

The kernels release the GIL; one part of the image rows runs per compositing thread, in a
thread pool of Python threads (which wait on a lock, never spin). Their number is
`set_num_threads(n)`'s, else torch's (torch.get_num_threads()): velogauss.threads gives
torch one thread for its many small operations and these kernels one per core.
"""

import contextlib
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from velogauss_fast.backends import numba_kernels as nk

_POOL = None
_POOL_SIZE = 0
_POOL_LOCK = threading.Lock()
_THREADS = 0  # 0: follow torch.get_num_threads()


def set_num_threads(n):
    """Compositing threads of this backend (n >= 1), or 0 to follow torch.get_num_threads();
    returns the previous setting."""
    global _THREADS
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValueError(f"n: expected an integer >= 0 (0: torch's thread count), got {n!r}")
    previous, _THREADS = _THREADS, n
    return previous


def get_num_threads():
    """The compositing threads a render uses: set_num_threads's, else torch's."""
    return _THREADS or torch.get_num_threads()


@contextlib.contextmanager
def num_threads(n):
    """`set_num_threads(n)` for the renders inside the block, the previous setting after it.
    A render's backward uses the parts of its forward, so a render started inside keeps them."""
    previous = set_num_threads(n)
    try:
        yield
    finally:
        set_num_threads(previous)


def _run_parts(kernel, n_parts, *args):
    """kernel(part, n_parts, *args) for every part, in parallel; returns the results in part order.

    The calling thread runs part 0 itself and the pool the others: one thread fewer to wake,
    and the caller, already on a core, never waits idle for a pool thread to be scheduled.
    """
    global _POOL, _POOL_SIZE
    if n_parts == 1:
        return [kernel(0, 1, *args)]
    with _POOL_LOCK:
        if _POOL_SIZE < n_parts - 1:
            if _POOL is not None:
                _POOL.shutdown(wait=False)
            _POOL = ThreadPoolExecutor(max_workers=n_parts - 1, thread_name_prefix="velogauss-numba")
            _POOL_SIZE = n_parts - 1
        pool = _POOL
    others = [pool.submit(kernel, k, n_parts, *args) for k in range(1, n_parts)]
    first = kernel(0, n_parts, *args)
    return [first] + [f.result() for f in others]


def _parameters(rgb, spans):
    """The kernels' (n, N_COLUMNS) float64 parameter rows, in depth order: spans.geom, then rgb."""
    geom = spans.geom.numpy()
    prm = np.empty((geom.shape[0], geom.shape[1] + 3))
    prm[:, :geom.shape[1]] = geom
    np.take(as_float64(rgb), spans.ids.numpy(), axis=0, out=prm[:, geom.shape[1]:])
    return prm


def as_float64(x):
    """A float64, C-contiguous NumPy array of CPU tensor x (a view when x already is one).

    The backends' glue between torch and the kernels is NumPy, never torch: a torch operation
    opens an OpenMP region on each of torch's threads, whose workers spin against a busy
    process beside a library user's script (benchmarks/RESULTS.md, "Library use"); NumPy's
    casts, copies and sums run on the calling thread. bfloat16, which NumPy does not hold, is
    cast by torch."""
    x = x.detach()
    if x.dtype == torch.bfloat16:
        x = x.to(torch.float64)
    return np.ascontiguousarray(x.numpy(), dtype=np.float64)


def as_tensor(a, dtype):
    """Tensor of `dtype` (float32 or float64) from NumPy array a, cast by NumPy (see `as_float64`).
    Other dtypes (half precision, which NumPy may not hold) are cast by torch."""
    target = {torch.float32: np.float32, torch.float64: np.float64}.get(dtype)
    if target is None:
        return torch.from_numpy(a).to(dtype)
    return torch.from_numpy(np.ascontiguousarray(a, dtype=target))


class CompositeNumba(torch.autograd.Function):
    """Per-pixel front-to-back compositing of VG-RENDER's pairs in the numba kernels.

    Inputs mean2d (N, 2), conic (N, 3), opacity (N,), rgb (N, 3), background (3,) and
    spans (velogauss_fast.spans.Spans, CPU); outputs image (P, 3) and final
    transmittance T (P,), P = height * width, in the working dtype. Same outputs and
    gradients as velogauss_fast.composite.Composite up to rounding.
    """

    @staticmethod
    def forward(ctx, mean2d, conic, opacity, rgb, background, spans):
        n_pix = spans.width * spans.height
        prm = _parameters(rgb, spans)
        color = np.zeros((n_pix, 3))
        trans = np.ones(n_pix)
        last = np.full(n_pix, -1, dtype=np.int64)
        done = np.zeros(n_pix, dtype=np.uint8)
        n_parts = max(1, min(get_num_threads(), spans.height))
        counts = np.zeros(n_parts, dtype=np.int64)
        nk.count_pairs(n_parts, prm, spans.width, counts)
        alphas = [np.empty(c) for c in counts]
        _run_parts(_forward_part, n_parts, prm, spans.width, color, trans, last, done, alphas)
        image = color + trans[:, None] * as_float64(background)
        ctx.save_for_backward(background)
        ctx.prm, ctx.trans, ctx.last = prm, trans, last
        ctx.spans, ctx.alphas = spans, alphas
        ctx.n = mean2d.shape[0]
        dtype = mean2d.dtype
        return as_tensor(image, dtype), as_tensor(trans, dtype)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_image, g_T):
        (background,) = ctx.saved_tensors
        prm, T_final, last, spans, dtype = ctx.prm, ctx.trans, ctx.last, ctx.spans, background.dtype
        g_image = as_float64(g_image)
        # image = ... + T_final * background: the background term joins dL/dT_final.
        g_tf = as_float64(g_T) + g_image @ as_float64(background)
        g_background = as_tensor(T_final @ g_image, dtype)
        alphas = ctx.alphas
        n_parts = len(alphas)
        grads = np.zeros((n_parts, prm.shape[0], nk.N_GRAD))
        _run_parts(_backward_part, n_parts, prm, spans.width, g_image, T_final.copy(), T_final * g_tf, last,
                   alphas, grads)
        # Parts summed in a fixed order: the result does not depend on thread scheduling.
        per_gaussian = np.zeros((ctx.n, nk.N_GRAD))
        per_gaussian[spans.ids.numpy()] = grads.sum(0)
        g_mean2d, g_conic, g_opacity, g_rgb = as_tensor(per_gaussian, dtype).split([2, 3, 1, 3], dim=1)
        return g_mean2d, g_conic, g_opacity.squeeze(1), g_rgb, g_background, None


def _forward_part(part, n_parts, prm, width, color, trans, last, done, alphas):
    """One part's forward, filling its own alpha buffer."""
    nk.composite_forward(part, n_parts, prm, width, color, trans, last, done, alphas[part])


def _backward_part(part, n_parts, prm, width, g_image, trans, behind, last, alphas, grads):
    """One part's backward, from its own alpha buffer into its own slice of grads (parts, n, N_GRAD)."""
    nk.composite_backward(part, n_parts, prm, width, g_image, trans, behind, last, alphas[part], grads[part])
