"""Training scheme (b) in torch: the ADF carries the Gaussians through the observed window, the
velocity carries the ADF's state one step, and alone beyond the window.

Twin of `velogauss_ref.motion.carry` (spec/motion.md, VG-ADF-STATE, VG-STEP, VG-CARRY).
"""

import torch

from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.motion.trajectory import base_state, normalize_quat
from velogauss_fast.quaternion import quat_multiply


def adf_state(params, x0, q0, s0, z, t, cfg):
    """compose_state(x0, q0, s0, adf_residual(x0, t, z)) (VG-ADF-STATE); shapes as the reference."""
    return compose_state(x0, q0, s0, *adf_residual(params, x0, t, z, cfg))


def carried_state(params, x0, q0, s0, z, t, t_start, h, method, cfg):
    """The ADF's state at t_start advanced to t by the velocity, the start entering the step
    as a constant (VG-CARRY). x0 (N, 3), q0 (N, 4), s0 (N, 3), z (N, L) -> x (N, 3),
    q (N, 4) unit, s (N, 3); see `velogauss_ref.motion.carry.carried_state`."""
    xa, qa, sa = adf_state(params, x0, q0, s0, z, t_start, cfg)
    xs, qs, ss = xa.detach(), qa.detach(), sa.detach()
    xv, qv, sv = base_state(params, xs, qs, ss, z, t, h, method, cfg, t0=t_start)
    conjugate = torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=qs.dtype, device=qs.device)
    turn = quat_multiply(qv, qs * conjugate)
    return xa + (xv - xs), normalize_quat(quat_multiply(turn, qa)), sa * (sv / ss)


def carry_loss(params, x0, q0, s0, z, t_a, t, h, method, cfg):
    """mean_i |base_state(sg(adf_state(t_a)), t_a -> t)_x - sg(adf_state(t)_x)|^2 (VG-LOSS-CARRY);
    see `velogauss_ref.motion.carry.carry_loss`. Returns a 0-d tensor."""
    with torch.no_grad():
        xa, qa, sa = adf_state(params, x0, q0, s0, z, t_a, cfg)
        target = adf_state(params, x0, q0, s0, z, t, cfg)[0]
    xv = base_state(params, xa, qa, sa, z, t, h, method, cfg, t0=t_a)[0]
    return ((xv - target) ** 2).sum() / max(x0.shape[0], 1)
