"""The 12 affine basis fields and their affine form A(w) x + b(w), in torch.

Twin of `velogauss_ref.motion.basis` (spec/motion.md, VG-BASIS; paper eq. 4). Both are
written out entry by entry: Phi is linear in x, so no autodiff is ever needed for it.
"""

import torch

from velogauss_fast.checks import check_array


def basis_matrix(x):
    """Phi(x): the 12 basis velocity fields at x, as columns (VG-BASIS).

    x: (..., 3) -> Phi: (..., 3, 12), columns translation w1..w3, rotation w4..w6 (omega x x),
    stretch w7..w9, shear w10..w12, so that Phi(x) w = A(w) x + b(w).
    """
    check_array("x", x, ("...", 3))
    px, py, pz = x.unbind(-1)
    o, i = torch.zeros_like(px), torch.ones_like(px)
    rows = [
        [i, o, o, o, pz, -py, px, o, o, py, o, pz],
        [o, i, o, -pz, o, px, o, py, o, px, pz, o],
        [o, o, i, py, -px, o, o, o, pz, o, py, px],
    ]
    return torch.stack([torch.stack(r, dim=-1) for r in rows], dim=-2)


def affine_from_coefficients(w):
    """(A(w), b(w)) with Phi(x) w = A(w) x + b(w) (VG-BASIS).

    w: (..., 12) -> A: (..., 3, 3), b: (..., 3). The antisymmetric part of A is the spin
    omega = (w4, w5, w6), its trace w7 + w8 + w9 the divergence; shear is symmetric, trace-free.
    """
    check_array("w", w, ("...", 12))
    (w1, w2, w3, w4, w5, w6, w7, w8, w9, w10, w11, w12) = w.unbind(-1)
    A = torch.stack(
        [
            w7, w10 - w6, w5 + w12,
            w10 + w6, w8, w11 - w4,
            w12 - w5, w11 + w4, w9,
        ],
        dim=-1,
    ).reshape(w.shape[:-1] + (3, 3))
    return A, w[..., :3]
