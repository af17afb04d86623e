"""Training scheme (b): the ADF carries the Gaussians through the observed window, the velocity
carries the ADF's state one step, and alone beyond the window.

spec/motion.md, VG-ADF-STATE, VG-STEP (`base_state` with a start time t0) and VG-CARRY.
"""

import autograd.numpy as np
from autograd.tracer import getval

from velogauss_ref.motion.deform import adf_residual, compose_state
from velogauss_ref.motion.trajectory import base_state, normalize_quat
from velogauss_ref.quaternion import quat_multiply

# Conjugation of a quaternion (w, x, y, z) -> (w, -x, -y, -z): the inverse of a unit one.
_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0])


def adf_state(params, x0, q0, s0, z, t, cfg):
    """The ADF's own state at time t (VG-ADF-STATE): the correction of VG-ADF composed with the
    canonical state, compose_state(x0, q0, s0, adf_residual(x0, t, z)).

    x0 (N, 3), q0 (N, 4) any norm, s0 (N, 3) positive, z (N, L), scalar t -> x (N, 3),
    q (N, 4) unit, s (N, 3).
    """
    return compose_state(x0, q0, s0, *adf_residual(params, x0, t, z, cfg))


def carried_state(params, x0, q0, s0, z, t, t_start, h, method, cfg):
    """The state at t of scheme (b) (VG-CARRY): the ADF's state at t_start advanced to t by the
    velocity (VG-STEP), with the ADF's state entering the velocity step as a constant.

    x0 (N, 3), q0 (N, 4), s0 (N, 3) canonical; z (N, L); scalars t, t_start; h, method as
    VG-INTEG -> x (N, 3), q (N, 4) unit, s (N, 3). With y_a = adf_state(t_start) and
    y_v = base_state(stop(y_a), t_start -> t):
    x = x_a + (x_v - stop(x_a)),  q = normalise((q_v (x) stop(q_a)*) (x) q_a),  s = s_a (s_v / stop(s_a)).
    The values are y_v's; the velocity learns from the step alone, and the ADF's state gets
    the gradient of the carried state as if the step were a fixed displacement.
    t_start = t returns adf_state(t) exactly (a step of length 0).
    """
    xa, qa, sa = adf_state(params, x0, q0, s0, z, t_start, cfg)
    xs, qs, ss = getval(xa), getval(qa), getval(sa)
    xv, qv, sv = base_state(params, xs, qs, ss, z, t, h, method, cfg, t0=t_start)
    turn = quat_multiply(qv, qs * _CONJUGATE)
    return xa + (xv - xs), normalize_quat(quat_multiply(turn, qa)), sa * (sv / ss)


def carry_loss(params, x0, q0, s0, z, t_a, t, h, method, cfg):
    """Mean squared distance between the velocity's step and the ADF's path (VG-LOSS-CARRY).

    x0 (N, 3), q0 (N, 4), s0 (N, 3) canonical, z (N, L); scalars t_a, t in the observed
    window -> scalar: mean_i |x_v,i - sg(x_a(t))_i|^2 with x_v = base_state(sg(adf_state(t_a)),
    t_a -> t) (VG-STEP) and x_a(t) the ADF's position at t (VG-ADF-STATE). Only the velocity
    (and the code through it) learns: the ADF's states are constants. N = 0 gives 0.
    """
    n = np.shape(x0)[0]
    xa, qa, sa = (getval(v) for v in adf_state(params, x0, q0, s0, z, t_a, cfg))
    target = getval(adf_state(params, x0, q0, s0, z, t, cfg)[0])
    xv = base_state(params, xa, qa, sa, z, t, h, method, cfg, t0=t_a)[0]
    return np.sum((xv - target) ** 2) / max(n, 1)
