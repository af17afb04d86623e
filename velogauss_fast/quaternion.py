"""Quaternions (w, x, y, z): rotation matrices and Hamilton products, in torch.

Twin of `velogauss_ref.quaternion` (spec/rendering.md, VG-QUAT and VG-QUAT-MUL).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_core.constants import QUAT_ZERO_NORM_SQ


def quat_to_rotmat(q):
    """Rotation matrix of a quaternion (VG-QUAT).

    q: (..., 4) in (w, x, y, z), any norm -> R: (..., 3, 3), built from q / |q|.
    A quaternion with |q|^2 < QUAT_ZERO_NORM_SQ (zero, denormal) gives the identity, and
    its gradient is exactly zero (no NaN). q and -q give the same R.
    """
    check_array("q", q, ("...", 4))
    n2 = (q * q).sum(-1, keepdim=True)
    zero = n2 < QUAT_ZERO_NORM_SQ
    # Substitute a unit quaternion before dividing so that neither the forward nor the
    # backward pass of the discarded branch sees 0/0.
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=q.dtype, device=q.device)
    q_safe = torch.where(zero, identity, q)
    n2_safe = torch.where(zero, torch.ones_like(n2), n2)
    w, x, y, z = (q_safe / torch.sqrt(n2_safe)).unbind(-1)
    R = torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(q.shape[:-1] + (3, 3))
    return R


def quat_multiply(a, b):
    """Hamilton product a (x) b, not normalised (VG-QUAT-MUL).

    a, b: (..., 4) in (w, x, y, z), broadcastable -> (..., 4); R(a (x) b) = R(a) R(b).
    """
    check_array("a", a, ("...", 4))
    check_array("b", b, ("...", 4))
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        dim=-1,
    )


def normalize_quat(q):
    """q / |q| for q: (..., 4) (VG-QUAT); |q|^2 < QUAT_ZERO_NORM_SQ gives (1, 0, 0, 0) with zero gradient.

    The one normalisation of the fast path (spec/conventions.md, "Quaternions"): a zero or
    denormal quaternion is the identity rotation, as in `quat_to_rotmat`.
    """
    n2 = (q * q).sum(-1, keepdim=True)
    zero = n2 < QUAT_ZERO_NORM_SQ
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=q.dtype, device=q.device)
    # Divide a stand-in where q is ~0 so that neither pass of the discarded branch sees 0/0.
    q_safe = torch.where(zero, identity, q)
    return q_safe / torch.sqrt(torch.where(zero, torch.ones_like(n2), n2))
