"""Rotation and log-scale rates of a Gaussian carried by an affine velocity field, in torch.

Twin of `velogauss_ref.motion.rotscale` (spec/motion.md, VG-ROTSCALE).
"""

from velogauss_fast.checks import check_array
from velogauss_fast.motion.generators import block_generator, strain_generator
from velogauss_fast.motion.rates import GROUP_COLUMNS, axis_products, outer, rotmat, strain_rates


def rotscale_rates(q, w):
    """(q_dot, d log s / dt) of Gaussians in the field Phi(x) w, with grad v = A(w) (VG-ROTSCALE).

    q: (N, 4) (w, x, y, z), need not be unit; w: (N, 12) -> q_dot: (N, 4), log_s_dot: (N, 3).
    q_dot = 1/2 (0, omega) (x) q with omega = (w4, w5, w6) (the spin of A), and
    log_s_dot = diag(R(q)^T D R(q)) with D = (A + A^T) / 2 (the rate of strain along each
    principal axis). A zero quaternion (|q|^2 < QUAT_ZERO_NORM_SQ) has R = I and q_dot = 0.
    """
    check_array("q", q, (None, 4))
    check_array("w", w, (q.shape[0], 12))
    # base_state's per-stage kernels (velogauss_fast.motion.rates) on component-major views.
    _, omega, w_strain = w.T.split([len(cols) for cols in GROUP_COLUMNS.values()])
    T = block_generator(GROUP_COLUMNS["rotation"], ("q",), ("q",), q.dtype, q.device)
    E = strain_generator(GROUP_COLUMNS["strain"], q.dtype, q.device)
    q_dot = T @ outer(omega, q.T)
    log_s_dot = strain_rates(w_strain, axis_products(rotmat(q.T)), E)
    return q_dot.T, log_s_dot.T
