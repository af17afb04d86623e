"""Particle velocity Phi(x) w, the Eulerian velocity field v(x, t) and the no-pds MLP velocity, in torch.

Twin of `velogauss_ref.motion.velocity` (spec/motion.md, VG-VEL, VG-FIELD and VG-VEL-MLP).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import affine_from_coefficients
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import coefficients
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import mlp, positional_encoding


def velocity(x, w):
    """v = Phi(x) w = A(w) x + b(w) (VG-VEL).

    x: (N, 3) positions; w: (..., N, 12) coefficients -> v: (..., N, 3), world units per
    unit time. Leading dimensions of w are batch dimensions over the same points (the
    residuals pass one coefficient set per axis). Evaluated in affine form (no (N, 3, 12)
    basis tensor is built).
    """
    check_array("x", x, (None, 3))
    check_array("w", w, ("...", x.shape[0], 12))
    A, b = affine_from_coefficients(w)
    # Elementwise products and a 3-term sum beat a batched 3x3 matmul for large N.
    return (A * x[..., None, :]).sum(-1) + b


def velocity_field(params, x, t, cfg):
    """v(x, t) = Phi(x) w(t, E(gamma(x))): the code is taken at the query point (VG-FIELD).

    params: motion parameter dict; x: (N, 3) query points; t: scalar time; cfg: MotionSpec
    -> v: (N, 3). This is the field the physics residuals constrain.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    return velocity(x, coefficients(params, t, physics_code(params, x, cfg), cfg))


def mlp_velocity(params, x, t, cfg):
    """v(x, t) = MLP_v([gamma(x), t]): the unconstrained velocity of the "no-pds" ablation (VG-VEL-MLP).

    params: dict with "velocity_mlp" (layers 3 (1 + 2 cfg.n_freqs_x) + 1 -> hidden^depth -> 3);
    x: (N, 3) points; t: scalar time (number or 0-d tensor); cfg: MotionSpec -> v: (N, 3).
    No code, no basis: it moves positions only (the paper's replacement of the PDS).
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    t_col = time_tensor(t, x).reshape(1, 1).expand(x.shape[0], 1)
    return mlp(params["velocity_mlp"], torch.cat([positional_encoding(x, cfg.n_freqs_x), t_col], dim=-1))
