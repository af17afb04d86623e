"""Walkthrough part: the residual auxiliary deformation field on top of the physical motion
(VG-ADF, VG-ADF-COMPOSE)."""

import numpy as np

from velogauss_ref.motion.code import physics_code
from velogauss_core.motion import init_motion_params
from velogauss_ref.motion.deform import adf_residual, compose_state
from velogauss_ref.motion.trajectory import base_state
from velogauss.walkthrough.figures import new_figure, save
from velogauss.walkthrough.printing import Section, session
from velogauss.walkthrough.setups import CFG, axis_angle_quat, learned_motion_params

X0 = np.array([[-0.6, 0.3, 0.0], [0.7, -0.4, 0.2]])
Q0 = np.tile(axis_angle_quat([0, 0, 1], 0), (2, 1))
S0 = np.full((2, 3), 0.1)
STEP, METHOD = 1 / 16, "rk4"


def adf_section(figures):
    """VG-ADF: the correction of a trained-looking ADF and of a fresh one (the identity)."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    fresh = init_motion_params(np.random.default_rng(0), CFG)
    dx, dq, ds = adf_residual(params, X0, 0.5, z, CFG)
    fresh_dx, fresh_dq, fresh_ds = adf_residual(fresh, X0, 0.5, physics_code(fresh, X0, CFG), CFG)
    return Section(
        "Real scenes also hold motion that no locally affine field explains (cloth folds, small "
        "wobbles). An MLP of the canonical position, time and code predicts a correction of "
        "position, rotation and log-scale on top of the integrated base state. It is a residual: "
        "its last layer starts at zero, so a fresh model is purely physical (the second call below), "
        "and the physics loss never sees it, so it can only add detail the physical motion misses.",
        [session({"x0": X0, "t": 0.5}, "dx, dq, ds = adf_residual(params, x0, t, z, cfg)  # a trained-looking ADF",
                 {"dx": dx, "dq": dq, "ds": ds},
                 "adf_residual(fresh_params, x0, t, z, cfg)  # init_motion_params: the identity correction",
                 {"dx": fresh_dx, "dq": fresh_dq, "ds": fresh_ds})],
    )


def compose_section(figures):
    """VG-ADF-COMPOSE: base state at t = 0.5 corrected by the ADF; paths with and without it."""
    params = learned_motion_params()
    z = physics_code(params, X0, CFG)
    x_star, q_star, s_star = base_state(params, X0, Q0, S0, z, 0.5, STEP, METHOD, CFG)
    dx, dq, ds = adf_residual(params, X0, 0.5, z, CFG)
    x, q, s = compose_state(x_star, q_star, s_star, dx, dq, ds)
    return Section(
        "The state that is rendered is the base state corrected by the ADF (paper eq. 6): positions "
        "add, rotations compose (the correction acts in the base state's frame) and scales multiply "
        "by `exp(Δs)`, so they stay positive. The example corrects the base state at t = 0.5 of the "
        "two particles above.",
        [session("x_star, q_star, s_star = base_state(params, x0, q0, s0, z, t=0.5, h=1/16, method='rk4', cfg)",
                 {"x_star": x_star, "q_star": q_star, "s_star": s_star},
                 "x, q, s = compose_state(x_star, q_star, s_star, dx, dq, ds)", {"x": x, "q": q, "s": s}),
         _compose_figure(figures, params)],
    )


def _compose_figure(figures, params):
    x0 = np.array([[-0.6, 0.3, 0.0], [0.7, -0.4, 0.2], [0.0, 0.6, -0.3], [-0.3, -0.6, 0.4], [0.4, 0.2, -0.2]])
    q0, s0 = np.tile(axis_angle_quat([0, 0, 1], 0), (len(x0), 1)), np.full((len(x0), 3), 0.1)
    z = physics_code(params, x0, CFG)
    times = np.linspace(0, 1, 21)
    base, final = [], []
    for t in times:
        x_star, q_star, s_star = base_state(params, x0, q0, s0, z, t, STEP, METHOD, CFG)
        base.append(x_star)
        final.append(compose_state(x_star, q_star, s_star, *adf_residual(params, x0, t, z, CFG))[0])
    base, final = np.stack(base), np.stack(final)  # (T, N, 3)
    fig = new_figure(10, 4.2)
    ax_path, ax_size = fig.subplots(1, 2)
    for g in range(len(x0)):
        ax_path.plot(base[:, g, 0], base[:, g, 1], "-", color=f"C{g}")
        ax_path.plot(final[:, g, 0], final[:, g, 1], "--", color=f"C{g}")
        ax_path.plot(*x0[g, :2], "o", color=f"C{g}")
        for k in range(0, len(times), 5):
            ax_path.annotate("", final[k, g, :2], base[k, g, :2], arrowprops={"arrowstyle": "->", "color": "0.4"})
        ax_size.plot(times, np.linalg.norm(final[:, g] - base[:, g], axis=1), color=f"C{g}")
    ax_path.plot([], [], "k-", label="base state x*(t) (physical)")
    ax_path.plot([], [], "k--", label="x(t) = x*(t) + Δx (rendered)")
    ax_path.set(aspect="equal", xlabel="x", ylabel="y", title="paths, top view (dots: canonical positions)")
    ax_path.legend(fontsize=8)
    ax_size.set(xlabel="t", ylabel="|Δx|", title="size of the correction", ylim=(0, None))
    return save(fig, figures, "adf-correction",
                "The ADF on top of the physical motion: base-state paths x*(t) integrated through the velocity "
                "field (solid) and the corrected, rendered positions x*(t) + Δx (dashed; arrows at t = 0, 0.25, "
                "..., 1), for five particles of the example parameters.")


SECTIONS = {"VG-ADF": adf_section, "VG-ADF-COMPOSE": compose_section}
