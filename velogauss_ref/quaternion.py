"""Quaternions (w, x, y, z): rotation matrices and Hamilton products.

spec/rendering.md, VG-QUAT and VG-QUAT-MUL; conventions in spec/conventions.md ("Quaternions").
"""

import autograd.numpy as np
import numpy as onp

from velogauss_ref.checks import check_array
from velogauss_core.constants import QUAT_ZERO_NORM_SQ

# The quaternion of no rotation, (w, x, y, z) = (1, 0, 0, 0).
IDENTITY_QUAT = onp.array([1.0, 0.0, 0.0, 0.0])


def quat_to_rotmat(q):
    """Rotation matrix R of the normalised quaternion q / |q| (VG-QUAT).

    q: (..., 4) in (w, x, y, z), any norm -> R: (..., 3, 3).
    A quaternion with |q|^2 < QUAT_ZERO_NORM_SQ (zero, denormal) gives R = I with an exactly
    zero gradient (no NaN). q and -q give the same R. Non-finite or wrongly shaped q raises
    ValueError.
    """
    check_array("q", q, ("...", 4))
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    zero = n2 < QUAT_ZERO_NORM_SQ
    # Both branches of np.where are differentiated, so the identity branch is substituted
    # *before* dividing: the discarded branch never sees 0/0, forward or backward.
    q_safe = np.where(zero, np.array([1.0, 0.0, 0.0, 0.0]), q)
    n2_safe = np.where(zero, 1.0, n2)
    q_unit = q_safe / np.sqrt(n2_safe)
    w, x, y, z = q_unit[..., 0], q_unit[..., 1], q_unit[..., 2], q_unit[..., 3]
    R = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return np.reshape(R, np.shape(q)[:-1] + (3, 3))


def quat_multiply(a, b):
    """Hamilton product c = a (x) b, not normalised (VG-QUAT-MUL).

    a, b: (..., 4) in (w, x, y, z), broadcastable against each other -> c: (..., 4).
    Composes rotations as R(a (x) b) = R(a) R(b): b is applied first, then a.
    """
    check_array("a", a, ("...", 4))
    check_array("b", b, ("...", 4))
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def normalize_quat(q):
    """q / |q| for q: (..., 4) (VG-QUAT); |q|^2 < QUAT_ZERO_NORM_SQ gives (1, 0, 0, 0) with zero gradient.

    The stand-in is substituted before dividing, so neither branch of np.where sees 0 / 0,
    forward or backward (as in `quat_to_rotmat`).
    """
    n2 = np.sum(q * q, axis=-1, keepdims=True)
    zero = n2 < QUAT_ZERO_NORM_SQ
    q_safe = np.where(zero, IDENTITY_QUAT, q)
    return q_safe / np.sqrt(np.where(zero, 1.0, n2))
