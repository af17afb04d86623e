"""EWA projection of 3D Gaussians onto the image plane.

spec/rendering.md, VG-PROJ; camera and pixel conventions in spec/conventions.md.
"""

import autograd.numpy as np
import numpy as onp
from autograd.tracer import getval

from velogauss_core.checks import check_size, check_variance
from velogauss_ref.checks import check_array
from velogauss_core.constants import (
    ANTIALIAS_DET_RATIO_FLOOR,
    EIGEN_DISCRIMINANT_FLOOR,
    EPS2D,
    FAR_PLANE,
    FRUSTUM_GUARD,
    GAUSSIAN_EXTENT_SIGMA,
    NEAR_PLANE,
)


def project_gaussians(means, Sigma, viewmat, K, width, height, eps2d=EPS2D):
    """Project Gaussians to 2D: mean2d, depth, cov2d, conic, radius, valid (VG-PROJ).

    means: (N, 3) world mu; Sigma: (N, 3, 3) world covariances; viewmat: (4, 4)
    world-to-camera (OpenCV axes); K: (3, 3) intrinsics in pixels; width, height: image
    size in pixels (positive ints); eps2d: the dilation in px^2 (EPS2D, or the antialiased
    mode's MIP_FILTER_VARIANCE). Returns a dict of
      mean2d (N, 2) pixel coordinates (u, v), depth (N,) camera z,
      cov2d (N, 2, 2) px^2 (dilated by eps2d), conic (N, 3) = (a, b, c) of cov2d^-1,
      compensation (N,) in (0, 1], the antialiased mode's opacity factor
      sqrt(det(cov2d - eps2d I) / det(cov2d)),
      radius (N,) int64 px, valid (N,) bool.
    Culled (valid = False): depth outside [NEAR_PLANE, FAR_PLANE], det(cov2d) <= 0, or the
    box [u - r, u + r] x [v - r, v + r] disjoint from [0, width] x [0, height]. Culled
    entries stay finite but mean nothing: the depth used for division is replaced by 1
    and a non-positive determinant by 1, so neither values nor gradients are NaN.
    radius and valid are piecewise constant and carry no gradient.
    """
    check_array("means", means, (None, 3))
    n = np.shape(means)[0]
    check_array("Sigma", Sigma, (n, 3, 3))
    check_array("viewmat", viewmat, (4, 4))
    check_array("K", K, (3, 3))
    check_size("width", width)
    check_size("height", height)
    check_variance("eps2d", eps2d)

    # 1. Camera space.
    W = viewmat[:3, :3]
    p = np.dot(means, W.T) + viewmat[:3, 3]
    depth = p[:, 2]
    # 2. Near/far culling; culled Gaussians may sit at z = 0, so they divide by 1 instead.
    valid = (depth >= NEAR_PLANE) & (depth <= FAR_PLANE)
    z = np.where(valid, depth, 1.0)

    # 3. Mean.
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    u = fx * p[:, 0] / z + cx
    v = fy * p[:, 1] / z + cy
    mean2d = np.stack([u, v], axis=-1)

    # 4. Jacobian of the perspective map at the clamped point (t_x, t_y, z).
    J = _perspective_jacobian(p[:, 0], p[:, 1], z, fx, fy, cx, cy, width, height)

    # 5. 2D covariance, dilated.
    JW = np.matmul(J, W)
    raw = np.matmul(np.matmul(JW, Sigma), np.swapaxes(JW, -1, -2))
    cov2d = raw + eps2d * np.eye(2)

    # 6. Conic (inverse of cov2d), and the antialiased mode's opacity factor: the splat's
    # integral before the dilation over its integral after.
    s00, s01, s11 = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det = s00 * s11 - s01 * s01
    valid = valid & (det > 0)
    det_safe = np.where(det > 0, det, 1.0)
    conic = np.stack([s11, -s01, s00], axis=-1) / det_safe[:, None]
    det_raw = raw[:, 0, 0] * raw[:, 1, 1] - raw[:, 0, 1] * raw[:, 0, 1]
    compensation = np.sqrt(np.maximum(det_raw / det_safe, ANTIALIAS_DET_RATIO_FLOOR))

    # 7. Extent and 8. off-screen culling.
    radius = _radius(getval(cov2d))
    u_, v_, r = getval(u), getval(v), radius
    on_screen = (u_ + r >= 0) & (u_ - r <= width) & (v_ + r >= 0) & (v_ - r <= height)
    valid = valid & on_screen
    return {
        "mean2d": mean2d,
        "depth": depth,
        "cov2d": cov2d,
        "conic": conic,
        "compensation": compensation,
        "radius": radius,
        "valid": onp.asarray(valid),
    }


def _perspective_jacobian(px, py, z, fx, fy, cx, cy, width, height):
    """J (N, 2, 3) of (x, y, z) -> (fx x / z, fy y / z) at x/z, y/z clamped (VG-PROJ 4).

    The clamp limits are the image half-extents seen from the principal point plus
    FRUSTUM_GUARD tan(fov/2) (3DGS's 1.3 tan(fov/2) for a centred principal point), so a
    Gaussian far outside the frustum is not stretched into a huge on-screen smear.
    """
    tan_x = 0.5 * width / fx
    tan_y = 0.5 * height / fy
    lim_x_pos = (width - cx) / fx + FRUSTUM_GUARD * tan_x
    lim_x_neg = cx / fx + FRUSTUM_GUARD * tan_x
    lim_y_pos = (height - cy) / fy + FRUSTUM_GUARD * tan_y
    lim_y_neg = cy / fy + FRUSTUM_GUARD * tan_y
    tx = z * np.clip(px / z, -lim_x_neg, lim_x_pos)
    ty = z * np.clip(py / z, -lim_y_neg, lim_y_pos)
    zeros = np.zeros(np.shape(z))
    J = np.stack(
        [fx / z, zeros, -fx * tx / (z * z), zeros, fy / z, -fy * ty / (z * z)], axis=-1
    )
    return np.reshape(J, (np.shape(z)[0], 2, 3))


def _radius(cov2d):
    """ceil(GAUSSIAN_EXTENT_SIGMA sqrt(lambda_max(cov2d))) as int64 pixels (VG-PROJ 7).

    lambda_max = b + sqrt(max(EIGEN_DISCRIMINANT_FLOOR, b^2 - det)), b = trace / 2.
    Takes a plain array: the radius is piecewise constant and carries no gradient.
    """
    s00, s01, s11 = cov2d[:, 0, 0], cov2d[:, 0, 1], cov2d[:, 1, 1]
    det = s00 * s11 - s01 * s01
    b = 0.5 * (s00 + s11)
    lambda_max = b + onp.sqrt(onp.maximum(EIGEN_DISCRIMINANT_FLOOR, b * b - det))
    return onp.ceil(GAUSSIAN_EXTENT_SIGMA * onp.sqrt(lambda_max)).astype(onp.int64)
