"""Base state x*(t), q*(t), s*(t) of every particle by integration from t = 0, in torch.

Twin of `velogauss_ref.motion.trajectory` (spec/motion.md, VG-TRAJ).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.coefficients import _masked, _mixing, _patterns
from velogauss_fast.motion.integrate import integrate
from velogauss_fast.motion.rotscale import _rotscale_rates
from velogauss_fast.motion.scalars import check_time
from velogauss_fast.motion.velocity import _velocity
from velogauss_ref.constants import QUAT_ZERO_NORM_SQ


def base_state(params, x0, q0, s0, z, t, h, method, cfg):
    """Integrate (x, q, log s) from 0 to t in the per-particle field Phi(x) w(tau, z) (VG-TRAJ).

    params: motion parameter dict; x0: (N, 3) canonical means; q0: (N, 4) quaternions (any
    norm); s0: (N, 3) positive scales; z: (N, L) frozen physics codes; t: scalar target time
    (any real value; negative integrates backward); h > 0: maximum step; method: "euler" |
    "rk2" | "rk4"; cfg: MotionConfig -> x_t (N, 3), q_t (N, 4) unit, s_t (N, 3).
    The three are integrated jointly as one (N, 10) state; the mixing weights m(z) are
    computed once and the time network once per stage. t = 0 returns the canonical state
    (q normalised). A quaternion that stays below QUAT_ZERO_NORM_SQ comes back as the
    identity (1, 0, 0, 0). Raises ValueError for bad shapes, non-finite or non-positive s0.
    """
    check_array("x0", x0, (None, 3))
    n = x0.shape[0]
    check_array("q0", q0, (n, 4))
    check_array("s0", s0, (n, 3))
    if not bool((s0 > 0).all()):
        raise ValueError("s0: expected positive scales")
    check_array("z", z, (n, params["mix"][0][0].shape[0]))
    check_time("t", t)
    m = _mixing(params, z)  # [N, K], constant along the path: the code is frozen

    def rates(y, tau):
        x, q = y[:, :3], y[:, 3:7]
        w = _masked(m @ _patterns(params, tau, cfg), cfg)  # [N, 12]
        q_dot, log_s_dot = _rotscale_rates(q, w)
        return torch.cat([_velocity(x, w), q_dot, log_s_dot], dim=-1)

    y0 = torch.cat([x0, q0, torch.log(s0)], dim=-1)  # [N, 10]
    y = integrate(rates, y0, 0.0, t, h, method)
    return y[:, :3], normalize_quat(y[:, 3:7]), torch.exp(y[:, 7:])


def normalize_quat(q):
    """q / |q| for q: (..., 4); |q|^2 < QUAT_ZERO_NORM_SQ gives (1, 0, 0, 0) with zero gradient."""
    n2 = (q * q).sum(-1, keepdim=True)
    zero = n2 < QUAT_ZERO_NORM_SQ
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=q.dtype, device=q.device)
    # Divide a stand-in where q is ~0 so that neither pass of the discarded branch sees 0/0.
    q_safe = torch.where(zero, identity, q)
    return q_safe / torch.sqrt(torch.where(zero, torch.ones_like(n2), n2))
