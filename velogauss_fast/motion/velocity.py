"""Particle velocity Phi(x) w, the Eulerian velocity field v(x, t) and the no-pds MLP velocity, in torch.

Twin of `velogauss_ref.motion.velocity` (spec/motion.md, VG-VEL, VG-FIELD and VG-VEL-MLP).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import _affine
from velogauss_fast.motion.code import _code
from velogauss_fast.motion.coefficients import _coefficients
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import _encode, _mlp


def velocity(x, w):
    """v = Phi(x) w = A(w) x + b(w) (VG-VEL).

    x: (N, 3) positions; w: (N, 12) coefficients -> v: (N, 3), world units per unit time.
    Evaluated in affine form (no (N, 3, 12) basis tensor is built).
    """
    check_array("x", x, (None, 3))
    check_array("w", w, (x.shape[0], 12))
    return _velocity(x, w)


def velocity_field(params, x, t, cfg):
    """v(x, t) = Phi(x) w(t, E(gamma(x))): the code is taken at the query point (VG-FIELD).

    params: motion parameter dict; x: (N, 3) query points; t: scalar time; cfg: MotionConfig
    -> v: (N, 3). This is the field the physics residuals constrain.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    return _velocity_field(params, x, t, cfg)


def _velocity(x, w):
    A, b = _affine(w)
    # Elementwise products and a 3-term sum beat a batched 3x3 matmul for large N.
    return (A * x[..., None, :]).sum(-1) + b


def _velocity_field(params, x, t, cfg):
    return _velocity(x, _coefficients(params, t, _code(params, x, cfg), cfg))


def mlp_velocity(params, x, t, cfg):
    """v(x, t) = MLP_v([gamma(x), t]): the unconstrained velocity of the "no-pds" ablation (VG-VEL-MLP).

    params: dict with "velocity_mlp" (layers 3 (1 + 2 cfg.n_freqs_x) + 1 -> hidden^depth -> 3);
    x: (N, 3) points; t: scalar time (number or 0-d tensor); cfg: MotionConfig -> v: (N, 3).
    No code, no basis: it moves positions only (the paper's replacement of the PDS).
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    return _mlp_velocity(params, x, time_tensor(t, x).reshape(1, 1).expand(x.shape[0], 1), cfg)


def _mlp_velocity(params, x, t_col, cfg):
    """`mlp_velocity` at x (N, 3) with one time per point, t_col (N, 1)."""
    return _mlp(params["velocity_mlp"], torch.cat([_encode(x, cfg.n_freqs_x), t_col], dim=-1))
