"""VG-LOSS's photometric loss in a compiled CPU kernel: value and gradient in one pass.

`photometric_loss_numba(pred, gt, target)` is `velogauss_fast.losses.photometric_loss` (L1
plus LAMBDA_DSSIM times 1 - SSIM, VG-METRIC-SSIM's statistics) for CPU tensors. The torch
form runs the window as depthwise convolutions whose backward, on the CPU, costs about
twice their forward; here one loop per channel takes the window's column and row passes
over the centred maps x, x^2, xy (the ground truth's y, y^2 come from its `SSIMTarget`),
the SSIM map, and, when pred requires a gradient, the adjoint passes back to pred, in the
same call. The backward then only scales the saved gradient. float64 throughout whatever
the working dtype (inputs cast up, value and gradient cast back).
"""

import numba
import numpy as np
import torch

from velogauss_core.constants import LAMBDA_DSSIM, SSIM_K1, SSIM_K2
from velogauss_core.ssim_window import gaussian_window

_C1, _C2 = SSIM_K1**2, SSIM_K2**2
_WINDOW = gaussian_window()
# As the rasterizer's kernels: IEEE rounding, no Python division checks, cached, GIL released.
_JIT = dict(cache=True, nogil=True, error_model="numpy")


@numba.njit(**_JIT)
def photometric_kernel(x, y, x_mean, y_mean, mu_y, sq_y, g, lam, want_grad, grad):
    """(1 - lam) mean |x - y| + lam (1 - SSIM) of x, y (3, H, W) and, when want_grad, its
    gradient w.r.t. x into grad (3, H, W).

    x_mean, y_mean (3,): the channel means the statistics are centred on (a constant shift
    of VG-METRIC-SSIM); mu_y, sq_y (3, h, w): the window's mean of y - y_mean and of its
    square, h = H - len(g) + 1 (valid region); g: the 1D window.
    """
    n_ch, H, W = x.shape
    K = g.shape[0]
    h, w = H - K + 1, W - K + 1
    n_map, n_pix = n_ch * h * w, n_ch * H * W
    # Loops run with the column index innermost and no reduction across it, so that the
    # compiler vectorises them without reordering any sum (fastmath stays off).
    maps = np.empty((3, H, W))  # x, x^2, xy centred; later their adjoints
    col = np.empty((3, h, W))
    stat = np.empty((3, h, w))
    ssim_sum = 0.0
    l1_sum = 0.0
    smap = np.empty((h, w))
    for c in range(n_ch):
        xm, ym = x_mean[c], y_mean[c]
        for i in range(H):
            for j in range(W):
                xc = x[c, i, j] - xm
                maps[0, i, j] = xc
                maps[1, i, j] = xc * xc
                maps[2, i, j] = xc * (y[c, i, j] - ym)
        # The sums run in loops of their own, in the same order: an ordered sum cannot be
        # vectorised, and in the loops above it kept the compiler from vectorising the rest.
        for i in range(H):
            for j in range(W):
                l1_sum += abs(x[c, i, j] - y[c, i, j])
        # The window's column pass, then its row pass.
        col[:] = 0.0
        for m in range(3):
            for i in range(h):
                for k in range(K):
                    for j in range(W):
                        col[m, i, j] += g[k] * maps[m, i + k, j]
        stat[:] = 0.0
        for m in range(3):
            for i in range(h):
                for k in range(K):
                    for j in range(w):
                        stat[m, i, j] += g[k] * col[m, i, j + k]
        # The SSIM map; when wanted, its partial derivatives w.r.t. the three statistics
        # of x, in place of them (dL/dS = -lam / n_map for every map entry).
        gs = -lam / n_map
        for i in range(h):
            for j in range(w):
                mx, xx, xy = stat[0, i, j], stat[1, i, j], stat[2, i, j]
                my, yy = mu_y[c, i, j], sq_y[c, i, j]
                var_x, var_y, cov = xx - mx * mx, yy - my * my, xy - mx * my
                mxs, mys = mx + xm, my + ym
                a1, a2 = 2.0 * mxs * mys + _C1, 2.0 * cov + _C2
                b1, b2 = mxs * mxs + mys * mys + _C1, var_x + var_y + _C2
                s = (a1 * a2) / (b1 * b2)
                smap[i, j] = s
                g_a1, g_a2 = gs * a2 / (b1 * b2), gs * a1 / (b1 * b2)
                g_b1, g_b2 = -gs * s / b1, -gs * s / b2
                g_cov, g_var = 2.0 * g_a2, g_b2
                stat[0, i, j] = 2.0 * mys * g_a1 + 2.0 * mxs * g_b1 - 2.0 * mx * g_var - my * g_cov
                stat[1, i, j] = g_var
                stat[2, i, j] = g_cov
        for i in range(h):
            for j in range(w):
                ssim_sum += smap[i, j]
        if not want_grad:
            continue
        # Adjoint of the row pass, then of the column pass (into maps), then onto x through
        # x, x^2 and xy, plus the L1 term's sign.
        col[:] = 0.0
        for m in range(3):
            for i in range(h):
                for k in range(K):
                    for j in range(w):
                        col[m, i, j + k] += g[k] * stat[m, i, j]
        maps[:] = 0.0
        for m in range(3):
            for i in range(h):
                for k in range(K):
                    for j in range(W):
                        maps[m, i + k, j] += g[k] * col[m, i, j]
        for i in range(H):
            for j in range(W):
                d = x[c, i, j] - y[c, i, j]
                sign = 1.0 if d > 0 else -1.0 if d < 0 else 0.0
                xc = x[c, i, j] - xm
                grad[c, i, j] = ((1.0 - lam) / n_pix * sign
                                 + (maps[0, i, j] + 2.0 * xc * maps[1, i, j] + (y[c, i, j] - ym) * maps[2, i, j]))
    return (1.0 - lam) * l1_sum / n_pix + lam * (1.0 - ssim_sum / n_map)


def _channels_first(image):
    """(H, W, 3) tensor -> contiguous float64 NumPy (3, H, W)."""
    return image.detach().to(torch.float64).permute(2, 0, 1).contiguous().numpy()


def _f64(t):
    """A contiguous float64 NumPy copy of tensor t."""
    return t.detach().to(torch.float64).contiguous().numpy()


class PhotometricNumba(torch.autograd.Function):
    """VG-LOSS of pred (H, W, 3) against a checked gt and its SSIMTarget: a 0-d tensor in
    pred's dtype, differentiable in pred (the gradient computed by the forward)."""

    @staticmethod
    def forward(ctx, pred, gt, target):
        want_grad = ctx.needs_input_grad[0]
        grad = np.empty((3,) + tuple(pred.shape[:2])) if want_grad else np.empty((3, 0, 0))
        value = photometric_kernel(_channels_first(pred), _channels_first(gt),
                                   pred.detach().to(torch.float64).mean((0, 1)).numpy(),
                                   target.mean.to(torch.float64).reshape(3).numpy(), _f64(target.mu),
                                   _f64(target.sq), _WINDOW, LAMBDA_DSSIM, want_grad, grad)
        if want_grad:
            ctx.grad = torch.from_numpy(grad).permute(1, 2, 0).to(pred.dtype)
        return pred.new_tensor(value)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_value):
        return g_value * ctx.grad, None, None


def photometric_loss_numba(pred, gt, target):
    """`velogauss_fast.losses.photometric_loss(pred, gt, target)` in the kernel, for checked
    CPU tensors pred, gt (H, W, 3) and target = ssim_target(gt)."""
    return PhotometricNumba.apply(pred, gt, target)
