"""Base state x*(t), q*(t), s*(t) of every particle by integration from t = 0, in torch.

Twin of `velogauss_ref.motion.trajectory` (spec/motion.md, VG-TRAJ).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.coefficients import mixing_weights, motion_patterns_at
from velogauss_fast.motion.integrate import integrate_schedule, schedule
from velogauss_fast.motion.rates import axis_products, rate_plan, rotmat, state_rates
from velogauss_fast.motion.scalars import check_time, times_tensor
from velogauss_fast.quaternion import normalize_quat
from velogauss_core.constants import STAGE_CHUNK


def base_state(params, x0, q0, s0, z, t, h, method, cfg, t0=0.0):
    """Integrate (x, q, log s) from t0 to t in the per-particle field Phi(x) w(tau, z) (VG-TRAJ;
    VG-STEP: a start time t0 other than 0, the state (x0, q0, s0) then being the state at t0).

    params: motion parameter dict; x0: (N, 3) canonical means; q0: (N, 4) quaternions (any
    norm); s0: (N, 3) positive scales; z: (N, L) frozen physics codes; t: scalar target time
    (any real value; negative integrates backward); h > 0: maximum step; method: "euler" |
    "rk2" | "rk4"; cfg: MotionSpec -> x_t (N, 3), q_t (N, 4) unit, s_t (N, 3).
    Only what cfg.mask moves is integrated (`velogauss_fast.motion.rates`): without a
    rotation column q_t is q0 normalised, without a stretch or shear column s_t is s0 itself
    (both exactly what integrating their zero rates gives), and R(q0) is built once when log s
    moves but q does not. m(z) is computed once, the time network runs once per STAGE_CHUNK
    stage times, and the active coefficients of those stages come from one (stages x active,
    K) @ (K, N) product. t = 0 returns the canonical state (q normalised). A quaternion that stays
    below QUAT_ZERO_NORM_SQ comes back as the identity (1, 0, 0, 0). Raises ValueError for
    bad shapes or dtypes, a bad t, h or method. That s0 is positive, like that the input is
    finite, is the caller's to ensure (testing it would be a device sync per call): the
    model's scales are exp(log scales), the ADF's s* exp(ds).
    """
    check_array("x0", x0, (None, 3))
    n = x0.shape[0]
    check_array("q0", q0, (n, 4))
    check_array("s0", s0, (n, 3))
    check_array("z", z, (n, params["mix"][0][0].shape[0]))
    check_time("t", t)
    check_time("t0", t0)
    sched = schedule(t0, t, h, method)  # once: the stage times and the integration share it
    taus = sched.stage_times()
    plan = rate_plan(cfg.mask, x0.dtype, x0.device)
    lay = plan.layout
    if not lay.columns:
        return x0, normalize_quat(q0), s0  # w = 0: nothing moves, exactly as integrating 0
    stage_w = _stage_coefficients(params, z, taus, lay.columns, cfg)
    # R(q0) is constant when q is: its axis products are built once, not once per stage.
    RR0 = axis_products(rotmat(q0.T)) if lay.strain and not lay.rotation else None

    def rates(y, tau):
        # integrate calls f at `taus`, in that order: the next stage's coefficients are tau's.
        return state_rates(plan, next(stage_w), y, RR0)

    parts = [x0.T] + [q0.T] * lay.rotation + [torch.log(s0).T] * lay.strain
    y = integrate_schedule(rates, torch.cat(parts), sched)  # [rows, N], component-major
    q = y[3:7].T if lay.rotation else q0
    s = torch.exp(y[lay.width:].T) if lay.strain else s0
    return y[:3].T, normalize_quat(q), s


def _stage_coefficients(params, z, taus, columns, cfg):
    """The active coefficients w(tau, z)[:, columns] at every stage time tau, yielded in order
    as S tensors (a, N) (component-major, see `velogauss_fast.motion.rates`).

    Equal to `coefficients(...)` restricted to the mask's columns (the others are exactly 0):
    P at up to STAGE_CHUNK times from one run of the time network, then one matrix product
    with m(z), so integrating to a far time holds one chunk, not all S stages.
    """
    m = mixing_weights(params, z)  # [N, K], constant along the path: the code is frozen
    index = torch.tensor(columns, dtype=torch.long, device=m.device)
    for start in range(0, len(taus), STAGE_CHUNK):
        chunk = taus[start:start + STAGE_CHUNK]
        P = motion_patterns_at(params, times_tensor(chunk, params["time"][0][0]), cfg)  # [S', K, 12]
        P = P.index_select(2, index).transpose(1, 2).reshape(len(chunk) * len(columns), m.shape[1])  # [S' a, K]
        yield from (P @ m.T).split(len(columns))
