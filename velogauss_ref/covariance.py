"""3D covariance of a Gaussian from its rotation and scale (paper eq. 1).

spec/rendering.md, VG-COV.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array
from velogauss_ref.quaternion import quat_to_rotmat


def covariance_3d(quats, scales):
    """Sigma = R S S^T R^T with S = diag(s) and R = quat_to_rotmat(q) (VG-COV).

    quats: (N, 4) in (w, x, y, z), any norm (a zero quaternion is the identity rotation);
    scales: (N, 3) standard deviations s in world units (not logs; only s^2 enters, so
    the sign is irrelevant) -> Sigma: (N, 3, 3), symmetric positive semi-definite with
    eigenvalues s^2.
    """
    check_array("quats", quats, (None, 4))
    check_array("scales", scales, (np.shape(quats)[0], 3))
    R = quat_to_rotmat(quats)
    RS = R * scales[:, None, :]  # column k of R scaled by s_k
    return np.matmul(RS, np.swapaxes(RS, -1, -2))
