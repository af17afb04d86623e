"""3D covariance of a Gaussian from its rotation and scale, in torch.

Twin of `velogauss_ref.covariance` (spec/rendering.md, VG-COV; paper eq. 1).
"""

from velogauss_fast.checks import check_array
from velogauss_fast.quaternion import quat_to_rotmat


def covariance_3d(quats, scales):
    """Sigma = R S S^T R^T with S = diag(scales) and R = quat_to_rotmat(quats) (VG-COV).

    quats: (N, 4) (w, x, y, z), any norm; scales: (N, 3) standard deviations (world
    units; the sign is irrelevant since only s^2 enters) -> Sigma: (N, 3, 3), symmetric
    positive semi-definite with eigenvalues s^2.
    """
    check_array("quats", quats, (None, 4))
    check_array("scales", scales, (quats.shape[0], 3))
    M = quat_to_rotmat(quats) * scales[:, None, :]  # R S, [N, 3, 3]
    return M @ M.transpose(-1, -2)
