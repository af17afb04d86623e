"""Rasterization of projected Gaussians: splat opacity, blending, the full image.

spec/rendering.md, VG-ALPHA, VG-BLEND (paper eq. 2) and VG-RENDER. The renderer is a
literal loop over pixels and, per pixel, over the depth-sorted Gaussians that cover it:
slow on purpose, exact on purpose (it is the oracle of velogauss_fast.raster).
"""

import autograd.numpy as np
import numpy as onp
from autograd.tracer import getval

from velogauss_ref.checks import check_array
from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN
from velogauss_ref.covariance import covariance_3d
from velogauss_core.checks import check_degree, check_size
from velogauss_core.rendering import check_mode, dilation, splat_opacities
from velogauss_ref.projection import project_gaussians
from velogauss_ref.sh import sh_to_color, viewing_directions


def splat_alpha(pixel, mean2d, conic, opacity):
    """Opacity of a splat at pixel centres: alpha = min(ALPHA_MAX, o exp(-sigma)) (VG-ALPHA).

    pixel: (..., 2) pixel centres (u, v); mean2d: (..., 2); conic: (..., 3) = (a, b, c) of
    the inverse 2D covariance; opacity: (...) in [0, 1]; all broadcast -> alpha (...), with
    d = pixel - mean2d and sigma = (a d_u^2 + c d_v^2) / 2 + b d_u d_v.
    Skipped (alpha = 0, zero gradient) where sigma < 0 (a numerically indefinite conic) or
    alpha < ALPHA_MIN.
    """
    check_array("pixel", pixel, ("...", 2))
    check_array("mean2d", mean2d, ("...", 2))
    check_array("conic", conic, ("...", 3))
    check_array("opacity", opacity)
    d = pixel - mean2d
    d_u, d_v = d[..., 0], d[..., 1]
    a, b, c = conic[..., 0], conic[..., 1], conic[..., 2]
    sigma = 0.5 * (a * d_u * d_u + c * d_v * d_v) + b * d_u * d_v
    # exp(-sigma) overflows for a very negative sigma, and the discarded branch of
    # np.where is still differentiated (0 * inf = NaN): evaluate exp only where sigma >= 0.
    sigma_safe = np.where(sigma >= 0, sigma, 0.0)
    alpha = np.minimum(ALPHA_MAX, opacity * np.exp(-sigma_safe))
    keep = (sigma >= 0) & (alpha >= ALPHA_MIN)
    return np.where(keep, alpha, 0.0)


def blend(colors, alphas, background):
    """Front-to-back alpha blending of the splats covering one pixel (VG-BLEND, paper eq. 2).

    colors: (M, 3); alphas: (M,) sorted by increasing depth, 0 for a skipped splat;
    background: (3,) -> (color (3,), T the final transmittance, a scalar).
    color = sum_i colors_i alpha_i T_i + T background with T_i = prod_{j<i} (1 - alpha_j).
    The splat that would bring the transmittance below TRANSMITTANCE_MIN is not blended
    and ends the pixel (3DGS semantics). Weights alpha_i T_i and T sum to 1.
    """
    check_array("colors", colors, (None, 3))
    check_array("alphas", alphas, (np.shape(colors)[0],))
    check_array("background", background, (3,))
    color = np.zeros(3)
    T = np.ones(())
    for i in range(np.shape(alphas)[0]):
        if getval(alphas[i]) == 0:
            continue
        T_next = T * (1 - alphas[i])
        if getval(T_next) < TRANSMITTANCE_MIN:
            break
        color = color + colors[i] * alphas[i] * T
        T = T_next
    return color + T * background, T


def rasterize(means, quats, scales, opacities, colors, viewmat, K, width, height,
              background=None, sh_degree=None, mode="classic"):
    """Render one image of N Gaussians by a literal per-pixel loop (VG-RENDER).

    means (N, 3) world; quats (N, 4) (w, x, y, z); scales (N, 3) standard deviations;
    opacities (N,) in [0, 1]; colors (N, 3) RGB, or (N, K, 3) SH coefficients with
    K >= (sh_degree + 1)^2 when sh_degree in {0, 1, 2, 3} is given; viewmat (4, 4)
    world-to-camera (OpenCV axes); K (3, 3) intrinsics; width, height positive ints;
    background (3,) (default black); mode "classic" (dilation EPS2D) or "antialiased"
    (dilation MIP_FILTER_VARIANCE, each splat's opacity times VG-PROJ's compensation;
    velogauss_core.rendering).
    Returns image (H, W, 3), alpha (H, W, 1) = 1 - T, and meta: the VG-PROJ outputs
    (mean2d, depth, cov2d, conic, radius, valid), "colors" (N, 3) the RGB used and
    "n_pairs" the number of (valid Gaussian, pixel) pairs whose box holds the pixel centre.
    Pixel (i, j) is sampled at (j + 0.5, i + 0.5); it takes every valid Gaussian with
    u - r <= j + 0.5 <= u + r and v - r <= i + 0.5 <= v + r, in increasing depth (ties keep
    index order), alpha by VG-ALPHA, blended by VG-BLEND. N = 0 renders the background.
    Differentiable (autograd) w.r.t. means, quats, scales, opacities, colors, background.
    Bad input raises ValueError naming the argument.
    """
    check_array("means", means, (None, 3))
    n = np.shape(means)[0]
    check_array("quats", quats, (n, 4))
    check_array("scales", scales, (n, 3))
    check_array("opacities", opacities, (n,))
    if sh_degree is None:
        check_array("colors", colors, (n, 3))
    else:
        check_degree("sh_degree", sh_degree)
        check_array("colors", colors, (n, None, 3))
        if np.shape(colors)[1] < (sh_degree + 1) ** 2:
            raise ValueError(f"colors: sh_degree {sh_degree} needs {(sh_degree + 1) ** 2} "
                             f"SH coefficients, got {np.shape(colors)[1]}")
    check_array("viewmat", viewmat, (4, 4))
    check_array("K", K, (3, 3))
    check_size("width", width)
    check_size("height", height)
    if background is None:
        background = np.zeros(3)
    check_array("background", background, (3,))
    check_mode(mode)

    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height, dilation(mode))
    if sh_degree is None:
        rgb = colors
    else:
        rgb = sh_to_color(colors, viewing_directions(means, viewmat), sh_degree)
    opacities = splat_opacities(opacities, proj["compensation"], mode)

    valid_ids = onp.flatnonzero(proj["valid"])
    depth_order = valid_ids[onp.argsort(getval(proj["depth"])[valid_ids], kind="stable")]
    uv = getval(proj["mean2d"])
    r = proj["radius"]

    pixel_colors, pixel_T, n_pairs = [], [], 0
    for i in range(height):
        for j in range(width):
            centre = onp.array([j + 0.5, i + 0.5])
            covering = [
                g for g in depth_order
                if uv[g, 0] - r[g] <= centre[0] <= uv[g, 0] + r[g]
                and uv[g, 1] - r[g] <= centre[1] <= uv[g, 1] + r[g]
            ]
            n_pairs += len(covering)
            covering = onp.array(covering, dtype=onp.int64)
            alphas = splat_alpha(centre, proj["mean2d"][covering], proj["conic"][covering],
                                 opacities[covering])
            color, T = blend(rgb[covering], alphas, background)
            pixel_colors.append(color)
            pixel_T.append(T)

    image = np.reshape(np.stack(pixel_colors), (height, width, 3))
    alpha = np.reshape(1 - np.stack(pixel_T), (height, width, 1))
    meta = dict(proj, colors=rgb, n_pairs=n_pairs)
    return image, alpha, meta
