"""How a Gaussian's rotation and scale follow an affine velocity field.

spec/motion.md, VG-ROTSCALE.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array
from velogauss_ref.motion.basis import affine_from_coefficients
from velogauss_ref.quaternion import quat_multiply, quat_to_rotmat


def rotscale_rates(q, w):
    """(q_dot, d log s / dt) of Gaussians carried by the field Phi(x) w, grad v = A(w) (VG-ROTSCALE).

    q: (N, 4) quaternions (w, x, y, z), any norm; w: (N, 12) coefficients ->
    q_dot: (N, 4) = 1/2 (0, omega) (x) q with omega = (w4, w5, w6), the spin of A;
    log_s_dot: (N, 3) = diag(R(q)^T D R(q)) with D = (A + A^T) / 2, the strain rate along
    each principal axis (column of R). Rigid motion (D = 0) keeps the scales constant.
    A zero or denormal quaternion (|q|^2 < QUAT_ZERO_NORM_SQ) has R = I and q_dot = 0 (it
    stays zero). Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("q", q, (None, 4))
    check_array("w", w, (np.shape(q)[0], 12))
    omega = np.concatenate([np.zeros((np.shape(w)[0], 1)), w[:, 3:6]], axis=1)  # pure quaternion (0, omega)
    q_dot = 0.5 * quat_multiply(omega, q)
    A, _ = affine_from_coefficients(w)
    D = 0.5 * (A + np.swapaxes(A, 1, 2))
    R = quat_to_rotmat(q)
    # Entry k is r_k^T D r_k for the k-th principal axis r_k = R[:, k].
    log_s_dot = np.einsum("nik,nij,njk->nk", R, D, R)
    return q_dot, log_s_dot
