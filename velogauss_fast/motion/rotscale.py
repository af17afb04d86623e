"""Rotation and log-scale rates of a Gaussian carried by an affine velocity field, in torch.

Twin of `velogauss_ref.motion.rotscale` (spec/motion.md, VG-ROTSCALE).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import _affine
from velogauss_fast.quaternion import quat_multiply, quat_to_rotmat


def rotscale_rates(q, w):
    """(q_dot, d log s / dt) of Gaussians in the field Phi(x) w, with grad v = A(w) (VG-ROTSCALE).

    q: (N, 4) (w, x, y, z), need not be unit; w: (N, 12) -> q_dot: (N, 4), log_s_dot: (N, 3).
    q_dot = 1/2 (0, omega) (x) q with omega = (w4, w5, w6) (the spin of A), and
    log_s_dot = diag(R(q)^T D R(q)) with D = (A + A^T) / 2 (the rate of strain along each
    principal axis). A zero quaternion (|q|^2 < QUAT_ZERO_NORM_SQ) has R = I and q_dot = 0.
    """
    check_array("q", q, (None, 4))
    check_array("w", w, (q.shape[0], 12))
    return _rotscale_rates(q, w)


def _rotscale_rates(q, w):
    omega = torch.cat([torch.zeros_like(w[..., :1]), w[..., 3:6]], dim=-1)  # pure quaternion
    q_dot = 0.5 * quat_multiply(omega, q)
    A, _ = _affine(w)
    R = quat_to_rotmat(q)
    # diag(R^T D R) = diag(R^T A R): the spin part of A adds r^T Omega r = 0 on each axis r.
    # A R as three broadcast products: a batched 3x3 matmul is several times slower on CPU.
    AR = sum(A[..., :, j, None] * R[..., None, j, :] for j in range(3))
    log_s_dot = (AR * R).sum(-2)
    return q_dot, log_s_dot
