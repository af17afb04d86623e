"""The 12 affine basis velocity fields and their affine form A(w) x + b(w) (paper eq. 4).

spec/motion.md, VG-BASIS. Phi is linear in x, so both functions are written out entry by
entry; nothing here needs autodiff to be understood.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array


def basis_matrix(x):
    """Phi(x): the 12 basis velocity fields evaluated at x, one per column (VG-BASIS).

    x: (..., 3) positions -> Phi: (..., 3, 12), columns in the paper's order:
    translation w1..w3 (I), rotation w4..w6 (omega x x), stretch w7..w9 (diag(x, y, z)),
    shear w10..w12 (symmetric, trace-free). Non-finite or wrongly shaped x raises ValueError.
    """
    check_array("x", x, ("...", 3))
    px, py, pz = x[..., 0], x[..., 1], x[..., 2]
    o, i = np.zeros(np.shape(px)), np.ones(np.shape(px))
    rows = [
        # translation    rotation        stretch       shear
        [i, o, o,        o, pz, -py,     px, o, o,     py, o, pz],
        [o, i, o,        -pz, o, px,     o, py, o,     px, pz, o],
        [o, o, i,        py, -px, o,     o, o, pz,     o, py, px],
    ]
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def affine_from_coefficients(w):
    """(A(w), b(w)) such that Phi(x) w = A(w) x + b(w) for every x (VG-BASIS).

    w: (..., 12) coefficients -> A: (..., 3, 3), b: (..., 3) = (w1, w2, w3).
    The antisymmetric part of A is the spin omega = (w4, w5, w6) (curl 2 omega), its trace
    w7 + w8 + w9 the divergence, and the shear part is symmetric and trace-free.
    Non-finite or wrongly shaped w raises ValueError.
    """
    check_array("w", w, ("...", 12))
    w1, w2, w3, w4, w5, w6, w7, w8, w9, w10, w11, w12 = (w[..., k] for k in range(12))
    A = np.stack(
        [
            w7,       w10 - w6, w5 + w12,
            w10 + w6, w8,       w11 - w4,
            w12 - w5, w11 + w4, w9,
        ],
        axis=-1,
    )
    return np.reshape(A, np.shape(w)[:-1] + (3, 3)), w[..., 0:3]
