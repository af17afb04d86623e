"""Base state x*(t), q*(t), s*(t) of every particle, integrated from its canonical state.

spec/motion.md, VG-TRAJ.
"""

import autograd.numpy as np
import numpy as onp
from autograd.tracer import getval

from velogauss_ref.checks import check_array, check_scalar
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.motion.integrate import integrate
from velogauss_ref.motion.rotscale import rotscale_rates
from velogauss_ref.motion.velocity import velocity
from velogauss_ref.quaternion import normalize_quat

def base_state(params, x0, q0, s0, z, t, h, method, cfg, t0=0.0):
    """Integrate y = (x, q, log s) from t0 to t in the per-particle field Phi(x) w(tau, z) (VG-TRAJ;
    VG-STEP: a start time t0 other than 0, the state (x0, q0, s0) then being the state at t0).

    params: motion parameter dict; x0: (N, 3) canonical means; q0: (N, 4) quaternions, any
    norm; s0: (N, 3) positive scales; z: (N, L) physics codes, frozen along each path;
    t: scalar target time, any real value (t < 0 integrates backward); h > 0: largest step;
    method: "euler" | "rk2" | "rk4" (VG-INTEG); cfg: MotionSpec ->
    x_t (N, 3), q_t (N, 4) unit, s_t (N, 3) positive.
    The rates are x_dot = Phi(x) w and (q_dot, d log s/dt) = rotscale_rates(q, w), with
    w = coefficients(params, tau, z, cfg). t = 0 returns the canonical state (q0
    normalised). A quaternion that stays below QUAT_ZERO_NORM_SQ (zero has zero rate) comes
    back as the identity (1, 0, 0, 0). Bad shapes, non-finite input, non-positive s0, h <= 0
    or an unknown method raise ValueError.
    """
    check_array("x0", x0, (None, 3))
    n = np.shape(x0)[0]
    check_array("q0", q0, (n, 4))
    check_array("s0", s0, (n, 3))
    if not onp.all(getval(s0) > 0):
        raise ValueError("s0: expected positive scales")
    check_array("z", z, (n, np.shape(params["mix"][0][0])[0]))
    check_scalar("t", t)
    check_scalar("t0", t0)

    def rates(y, tau):
        x, q = y[:, 0:3], y[:, 3:7]
        w = coefficients(params, tau, z, cfg)
        q_dot, log_s_dot = rotscale_rates(q, w)
        return np.concatenate([velocity(x, w), q_dot, log_s_dot], axis=1)

    y0 = np.concatenate([x0, q0, np.log(s0)], axis=1)  # (N, 10)
    y = integrate(rates, y0, t0, t, h, method)
    return y[:, 0:3], normalize_quat(y[:, 3:7]), np.exp(y[:, 7:10])
