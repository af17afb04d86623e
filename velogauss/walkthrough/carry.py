"""Walkthrough part: training scheme (b), where the ADF carries the Gaussians through the window
and the velocity carries the ADF's state one step (VG-STEP, VG-ADF-STATE, VG-CARRY, VG-LOSS-CARRY)."""

import numpy as np

from velogauss_ref.motion.carry import adf_state, carried_state, carry_loss
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.trajectory import base_state
from velogauss.walkthrough.printing import Section, session
from velogauss.walkthrough.setups import CFG, axis_angle_quat, learned_motion_params

X0 = np.array([[-0.6, 0.3, 0.0], [0.7, -0.4, 0.2]])
Q0 = np.tile(axis_angle_quat([0, 0, 1], 0), (2, 1))
S0 = np.full((2, 3), 0.1)
STEP, METHOD = 1 / 16, "rk4"
OFFSET = 0.05  # the default model.carry_offset: one frame of 21


def step_section(figures):
    """VG-STEP: integrating 0 -> 0.25 -> 0.5 in two legs equals 0 -> 0.5 in one."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    x_mid, q_mid, s_mid = base_state(params, X0, Q0, S0, z, 0.25, STEP, METHOD, CFG)
    x_two = base_state(params, x_mid, q_mid, s_mid, z, 0.5, STEP, METHOD, CFG, t0=0.25)[0]
    x_one = base_state(params, X0, Q0, S0, z, 0.5, STEP, METHOD, CFG)[0]
    return Section(
        "The base state can start from any time t0, not only from the canonical t = 0: the state "
        "given is then the state at t0, and the field is integrated from t0 to t with the code "
        "frozen as before. Scheme (b) needs this to move a state it did not integrate (the ADF's) "
        "by one step. Two legs, 0 → 0.25 and 0.25 → 0.5, land where one integration from 0 does "
        "(up to the integrator's error, here RK4 with h = 1/16, whose stages fall on the same grid).",
        [session({"x0": X0},
                 "x_mid, q_mid, s_mid = base_state(params, x0, q0, s0, z, t=0.25, h=1/16, method='rk4', cfg)",
                 "x_two = base_state(params, x_mid, q_mid, s_mid, z, t=0.5, h, method, cfg, t0=0.25)[0]",
                 "x_one = base_state(params, x0, q0, s0, z, t=0.5, h, method, cfg)[0]",
                 {"x_two": x_two, "x_one": x_one})],
    )


def adf_state_section(figures):
    """VG-ADF-STATE: the ADF applied to the canonical state at two times."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    x_a, q_a, s_a = adf_state(params, X0, Q0, S0, z, 0.5, CFG)
    return Section(
        "Under scheme (b) the ADF is the motion inside the observed window: its correction is "
        "composed with the canonical state itself (VG-ADF-COMPOSE with x* = x0), not with an "
        "integrated base state. This is what the Gaussians look like at t under that scheme.",
        [session({"x0": X0, "t": 0.5}, "x_a, q_a, s_a = adf_state(params, x0, q0, s0, z, t, cfg)",
                 {"x_a": x_a, "q_a": q_a, "s_a": s_a})],
    )


def carry_section(figures):
    """VG-CARRY: the ADF's state one frame earlier carried to t by the velocity; a zero step."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    t = 0.5
    x_c = carried_state(params, X0, Q0, S0, z, t, t - OFFSET, STEP, METHOD, CFG)[0]
    x_a = adf_state(params, X0, Q0, S0, z, t, CFG)[0]
    x_0 = carried_state(params, X0, Q0, S0, z, t, t, STEP, METHOD, CFG)[0]
    return Section(
        "The rendered state of scheme (b) (the authors' released code): take the ADF's state one "
        "frame away from t (a random side in training) and let the velocity carry it to t in one "
        "step. The picture drives both networks: the velocity learns the local motion from a "
        "geometry the ADF already fits, and the ADF gets the gradient as if the step were a fixed "
        "displacement. Past the window the start is the ADF's state at max_time and the velocity "
        "alone integrates. Where the velocity agrees with the ADF's motion the carried state is the "
        "ADF's state at t; a step of length 0 returns it exactly.",
        [session({"t": t, "t_start": t - OFFSET},
                 "x_c = carried_state(params, x0, q0, s0, z, t, t_start, h, method, cfg)[0]",
                 "x_a = adf_state(params, x0, q0, s0, z, t, cfg)[0]  # the ADF's own position at t",
                 "x_0 = carried_state(params, x0, q0, s0, z, t, t, h, method, cfg)[0]  # zero step",
                 {"x_c": x_c, "x_a": x_a, "x_0": x_0})],
    )


def carry_loss_section(figures):
    """VG-LOSS-CARRY: the squared gap between the velocity's step and the ADF's path."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    losses = {f"t_a = {t_a:g}": carry_loss(params, X0, Q0, S0, z, t_a, 0.5, STEP, METHOD, CFG)
              for t_a in (0.5, 0.45, 0.25)}
    return Section(
        "An optional loss fits the velocity to the ADF's paths without the renderer: from the ADF's "
        "state at t_a, one velocity step to t should land on the ADF's position at t. Only the "
        "velocity learns from it (both ADF states are constants). The gap is 0 for t_a = t and "
        "grows with the distance the two motions disagree over.",
        [session({"t": 0.5}, "carry_loss(params, x0, q0, s0, z, t_a, t, h, method, cfg)", losses)],
    )


SECTIONS = {"VG-STEP": step_section, "VG-ADF-STATE": adf_state_section, "VG-CARRY": carry_section,
            "VG-LOSS-CARRY": carry_loss_section}
