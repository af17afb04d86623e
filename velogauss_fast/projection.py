"""EWA projection of 3D Gaussians onto the image plane, in torch.

Twin of `velogauss_ref.projection` (spec/rendering.md, VG-PROJ).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_core.constants import (
    ANTIALIAS_DET_RATIO_FLOOR,
    EIGEN_DISCRIMINANT_FLOOR,
    EPS2D,
    FAR_PLANE,
    FRUSTUM_GUARD,
    GAUSSIAN_EXTENT_SIGMA,
    NEAR_PLANE,
)
from velogauss_core.checks import check_size, check_variance

# Radii are capped here (and in the numba backend's kernels) before the integer cast: a
# splat wider than this covers any image we can allocate, and the cap keeps absurd
# covariances (float32 overflow in lambda_max) from turning into undefined integer casts.
RADIUS_CAP = float(2**40)


def project_gaussians(means, Sigma, viewmat, K, width, height, eps2d=EPS2D):
    """Project Gaussians to 2D: means, depths, covariances, conics, radii, validity (VG-PROJ).

    means: (N, 3) world; Sigma: (N, 3, 3) world covariances; viewmat: (4, 4) world-to-camera
    (OpenCV axes); K: (3, 3) intrinsics in pixels; width, height: image size in pixels;
    eps2d: the dilation (px^2) added to the 2D covariance (velogauss_core.rendering.dilation).
    Returns a dict of mean2d (N, 2) px, depth (N,), cov2d (N, 2, 2) px^2, conic (N, 3)
    (a, b, c of the inverse covariance), compensation (N,) in (0, 1] (the antialiased
    mode's opacity factor, sqrt of det before eps2d over det after), radius (N,) int64 px,
    valid (N,) bool.

    Culled (valid = False): depth outside [NEAR_PLANE, FAR_PLANE], det(cov2d) <= 0, or the
    box [u +- r] x [v +- r] disjoint from [0, width] x [0, height]. Culled entries stay
    finite (the depth used for division is replaced by 1, the determinant by 1) and their
    gradients are finite, but they mean nothing. The radius is computed from cov2d in
    float64 whatever the input dtype (as the reference does), so float32 inputs round to
    the same integer except when 3 sqrt(lambda_max) is within float32 noise of one.
    """
    check_array("means", means, (None, 3))
    n = means.shape[0]
    check_array("Sigma", Sigma, (n, 3, 3))
    check_array("viewmat", viewmat, (4, 4))
    check_array("K", K, (3, 3))
    check_size("width", width)
    check_size("height", height)
    check_variance("eps2d", eps2d)

    Wr = viewmat[:3, :3]
    p = means @ Wr.T + viewmat[:3, 3]  # [N, 3] camera space
    depth = p[:, 2]
    valid = (depth >= NEAR_PLANE) & (depth <= FAR_PLANE)
    # Culled Gaussians may sit at z = 0; dividing by a stand-in depth keeps every entry
    # (and its gradient) finite.
    z = torch.where(valid, depth, torch.ones_like(depth))

    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    u = fx * p[:, 0] / z + cx
    v = fy * p[:, 1] / z + cy
    mean2d = torch.stack([u, v], dim=-1)

    tan_x = 0.5 * width / fx
    tan_y = 0.5 * height / fy
    lim_xp = (width - cx) / fx + FRUSTUM_GUARD * tan_x
    lim_xn = cx / fx + FRUSTUM_GUARD * tan_x
    lim_yp = (height - cy) / fy + FRUSTUM_GUARD * tan_y
    lim_yn = cy / fy + FRUSTUM_GUARD * tan_y
    tx = z * torch.clamp(p[:, 0] / z, -lim_xn, lim_xp)
    ty = z * torch.clamp(p[:, 1] / z, -lim_yn, lim_yp)
    zeros = torch.zeros_like(z)
    J = torch.stack(
        [fx / z, zeros, -fx * tx / (z * z), zeros, fy / z, -fy * ty / (z * z)], dim=-1
    ).reshape(n, 2, 3)
    JW = J @ Wr
    raw = JW @ Sigma @ JW.transpose(-1, -2)
    cov2d = raw + eps2d * torch.eye(2, dtype=raw.dtype, device=raw.device)

    s00, s01, s11 = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det = s00 * s11 - s01 * s01
    valid = valid & (det > 0)
    det_safe = torch.where(det > 0, det, torch.ones_like(det))
    conic = torch.stack([s11, -s01, s00], dim=-1) / det_safe[:, None]
    det_raw = raw[:, 0, 0] * raw[:, 1, 1] - raw[:, 0, 1] * raw[:, 0, 1]
    compensation = torch.sqrt(torch.clamp(det_raw / det_safe, min=ANTIALIAS_DET_RATIO_FLOOR))

    radius = _radius(cov2d.detach())
    rf = radius.to(u.dtype)
    u_d, v_d = u.detach(), v.detach()
    on_screen = (u_d + rf >= 0) & (u_d - rf <= width) & (v_d + rf >= 0) & (v_d - rf <= height)
    valid = valid & on_screen
    return {
        "mean2d": mean2d,
        "depth": depth,
        "cov2d": cov2d,
        "conic": conic,
        "compensation": compensation,
        "radius": radius,
        "valid": valid,
    }


def _radius(cov2d):
    """ceil(GAUSSIAN_EXTENT_SIGMA sqrt(lambda_max(cov2d))) in float64, as int64 (VG-PROJ 7)."""
    c = cov2d.to(torch.float64)
    s00, s01, s11 = c[:, 0, 0], c[:, 0, 1], c[:, 1, 1]
    det = s00 * s11 - s01 * s01
    b = 0.5 * (s00 + s11)
    lam = b + torch.sqrt(torch.clamp(b * b - det, min=EIGEN_DISCRIMINANT_FLOOR))
    r = torch.ceil(GAUSSIAN_EXTENT_SIGMA * torch.sqrt(torch.clamp(lam, min=0.0)))
    return torch.nan_to_num(r, nan=0.0, posinf=RADIUS_CAP).clamp(max=RADIUS_CAP).to(torch.int64)
