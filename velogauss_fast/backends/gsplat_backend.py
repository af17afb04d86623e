"""gsplat's CUDA tile rasterizer behind velogauss's projection (backend="gsplat").

Projection (VG-QUAT, VG-COV, VG-PROJ), culling and colours (VG-SH) are velogauss_fast's
own, so near/far planes, the dilation, the Jacobian clamp, radii and validity are exactly ours
and meta["mean2d"] is the tensor gsplat differentiates. gsplat (>= 1.5, float32 only)
then does tile intersection and compositing, which differs from VG-RENDER in three ways:

* each pixel evaluates every Gaussian of its 16x16 tile, not only those whose box holds
  the pixel centre: outside its box a splat has sigma > 4.5, so the two agree whenever
  opacity * exp(-4.5) < ALPHA_MIN, i.e. opacity < 0.35;
* alpha is clamped at 0.999 (gsplat's constant), not ALPHA_MAX = 0.99;
* a pixel stops when T (1 - alpha) <= TRANSMITTANCE_MIN (ours: <).

tests/fast/test_gsplat_backend.py compares the two where these do not apply.
"""

import math

import torch

from velogauss_core.rendering import dilation, splat_opacities
from velogauss_fast.covariance import covariance_3d
from velogauss_fast.projection import project_gaussians
from velogauss_fast.sh import sh_to_color, viewing_directions

_TILE_SIZE = 16  # gsplat's default and only tested tile size
_INT32_MAX = 2**31 - 1


def rasterize_gsplat(means, quats, scales, opacities, colors, viewmat, K, width, height, background, sh_degree,
                     mode="classic"):
    """`velogauss_fast.raster.rasterize` with gsplat's CUDA compositing; same arguments and outputs.

    Computes in the input dtype up to the compositing, which runs in float32 (gsplat's
    kernels are float32 only); image and alpha come back in the input dtype.
    """
    from gsplat import isect_offset_encode, isect_tiles, rasterize_to_pixels

    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height, dilation(mode))
    if sh_degree is None:
        rgb = colors
    else:
        rgb = sh_to_color(colors, viewing_directions(means, viewmat), sh_degree)
    opacities = splat_opacities(opacities, proj["compensation"], mode)
    # gsplat skips Gaussians with radius 0; our box is square, hence equal x and y radii.
    radius = torch.where(proj["valid"], proj["radius"], torch.zeros_like(proj["radius"]))
    radii = radius.clamp(max=_INT32_MAX).to(torch.int32)[:, None].expand(-1, 2)
    f32 = torch.float32
    mean2d = proj["mean2d"].to(f32)[None]
    tile_w, tile_h = math.ceil(width / _TILE_SIZE), math.ceil(height / _TILE_SIZE)
    _, isect_ids, flatten_ids = isect_tiles(
        mean2d.detach(), radii[None].contiguous(), proj["depth"].detach().to(f32)[None], _TILE_SIZE, tile_w, tile_h
    )
    offsets = isect_offset_encode(isect_ids, 1, tile_w, tile_h).reshape(1, tile_h, tile_w)
    image, alpha = rasterize_to_pixels(
        mean2d,
        proj["conic"].to(f32)[None],
        rgb.to(f32)[None],
        opacities.to(f32)[None],
        width,
        height,
        _TILE_SIZE,
        offsets,
        flatten_ids,
        backgrounds=background.to(f32)[None],
    )
    meta = dict(proj, colors=rgb, n_pairs=None)
    return image[0].to(means.dtype), alpha[0].to(means.dtype), meta
