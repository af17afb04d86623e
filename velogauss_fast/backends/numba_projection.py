"""The numba backend's per-view preparation: VG-COV, VG-PROJ and VG-SH in compiled kernels.

`prepare_numba` returns what `velogauss_fast.raster.prepare_torch` does (the VG-PROJ dict,
the RGB colours, the opacities VG-RENDER composites) from one autograd node whose forward
and backward are the loops of `numba_projection_kernels`, instead of the few hundred torch
operations of the torch path. The kernels compute in float64 whatever the working dtype
(inputs cast up, outputs and gradients cast back), so a float32 preparation differs from
the reference only by its float32 inputs. They give no gradient to the camera: `rasterize`
takes the torch path when viewmat or K requires one.
"""

import numpy as np
import torch

from velogauss_core.rendering import dilation
from velogauss_fast.backends import numba_projection_kernels as nk
from velogauss_fast.backends.numba_backend import as_float64, as_tensor


class ProjectNumba(torch.autograd.Function):
    """VG-COV, VG-PROJ, VG-SH and the composited opacities of N Gaussians in one view.

    Inputs means (N, 3), quats (N, 4), scales (N, 3), opacities (N,), sh (N, K, 3) or None
    (RGB colours: no SH), viewmat (4, 4), K (3, 3), width, height, eps2d, sh_degree (None
    with sh None), antialiased. Outputs mean2d (N, 2), depth (N,), cov2d (N, 2, 2), conic
    (N, 3), compensation (N,), opacities (N,) as composited, rgb (N, 3) (zeros without SH),
    radius (N,) int64, valid (N,) bool; the last two are not differentiable.
    """

    @staticmethod
    def forward(ctx, means, quats, scales, opacities, sh, viewmat, K, width, height, eps2d, sh_degree, antialiased):
        n, dtype = means.shape[0], means.dtype
        vm = as_float64(viewmat)
        sh64 = np.zeros((n, 0, 3)) if sh is None else as_float64(sh)
        args = (as_float64(means), as_float64(quats), as_float64(scales), as_float64(opacities), sh64, -1 if sh_degree is None else sh_degree,
                np.ascontiguousarray(vm[:3, :3]), np.ascontiguousarray(vm[:3, 3]),
                as_float64(K)[[0, 1, 0, 1], [0, 1, 2, 2]], float(width), float(height), float(eps2d),
                bool(antialiased))
        mean2d, depth, cov2d, conic = np.empty((n, 2)), np.empty(n), np.empty((n, 2, 2)), np.empty((n, 3))
        compensation, opacity_out, rgb = np.empty(n), np.empty(n), np.zeros((n, 3))
        radius, valid = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.uint8)
        nk.project_forward(*args, mean2d, depth, cov2d, conic, compensation, opacity_out, rgb, radius, valid)
        ctx.args, ctx.dtype, ctx.has_sh = args, dtype, sh is not None
        radius, valid = torch.from_numpy(radius), torch.from_numpy(valid).bool()
        ctx.mark_non_differentiable(radius, valid)
        floats = (as_tensor(a, dtype) for a in (mean2d, depth, cov2d, conic, compensation, opacity_out, rgb))
        return (*floats, radius, valid)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_mean2d, g_depth, g_cov2d, g_conic, g_compensation, g_opacity, g_rgb, _g_radius, _g_valid):
        args, dtype = ctx.args, ctx.dtype
        means, quats, scales, _, sh = args[:5]
        n = means.shape[0]
        g_means, g_quats, g_scales, g_opacities = np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 3)), np.empty(n)
        g_sh = np.empty(sh.shape)
        nk.project_backward(*args, as_float64(g_mean2d), as_float64(g_depth), as_float64(g_cov2d), as_float64(g_conic),
                            as_float64(g_compensation), as_float64(g_opacity), as_float64(g_rgb),
                            g_means, g_quats, g_scales, g_opacities, g_sh)
        out = [as_tensor(a, dtype) for a in (g_means, g_quats, g_scales, g_opacities)]
        return (*out, as_tensor(g_sh, dtype) if ctx.has_sh else None, *(None,) * 7)


def prepare_numba(means, quats, scales, opacities, colors, viewmat, K, width, height, sh_degree, mode):
    """`velogauss_fast.raster.prepare_torch` in the kernels: (VG-PROJ dict, rgb (N, 3),
    opacities (N,) as composited under `mode`). colors: (N, 3) RGB when sh_degree is None,
    else (N, K, 3) SH coefficients. CPU tensors; viewmat and K get no gradient."""
    sh = None if sh_degree is None else colors
    mean2d, depth, cov2d, conic, compensation, opacity_out, rgb, radius, valid = ProjectNumba.apply(
        means, quats, scales, opacities, sh, viewmat, K, width, height, dilation(mode), sh_degree,
        mode == "antialiased")
    proj = {"mean2d": mean2d, "depth": depth, "cov2d": cov2d, "conic": conic, "compensation": compensation,
            "radius": radius, "valid": valid}
    return proj, (colors if sh_degree is None else rgb), opacity_out
