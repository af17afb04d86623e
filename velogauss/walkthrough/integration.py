"""Walkthrough part: moving particles through time (VG-INTEG, VG-ROTSCALE, VG-TRAJ), and the first
place where accuracy costs time."""

import time

import numpy as np

from velogauss_ref.covariance import covariance_3d
from velogauss_ref.motion.code import physics_code
from velogauss_core.motion import INTEGRATORS as METHODS
from velogauss_ref.motion.integrate import integrate
from velogauss_ref.motion.rotscale import rotscale_rates
from velogauss_ref.motion.trajectory import base_state
from velogauss_ref.motion.velocity import velocity
from velogauss.walkthrough.figures import covariance_ellipse, new_figure, save
from velogauss.walkthrough.printing import Section, number, session, table, timings
from velogauss.walkthrough.setups import CFG, axis_angle_quat, coefficient_vector, constant_motion_params

OMEGA = 2 * np.pi  # one full turn about z over t in [0, 1]
STEPS = [2.0**-k for k in range(2, 8)]  # h = 1/4 .. 1/128; RK4's error stays far above rounding
FIGURE_STEP = 1 / 8
TIMING_REPEATS = 3
METHOD_COLOURS = {"euler": "tab:red", "rk2": "tab:orange", "rk4": "tab:green"}


def integration_section(figures):
    """VG-INTEG: Euler, RK2 and RK4 on a rigid rotation: errors, orders, work and (marked) wall times."""
    y0 = np.array([[1.0, 0.0, 0.0]])
    w = coefficient_vector(rotation=(0, 0, OMEGA))[None, :]
    calls = [0]

    def f(y, t):  # the rigid rotation v = ω × x (VG-VEL), counting its evaluations
        calls[0] += 1
        return velocity(y, w)

    runs = _solve_all(f, calls, y0)
    error = {key: float(np.linalg.norm(end - y0[0])) for key, (end, _, _) in runs.items()}  # exact: back at y0
    rows = []
    for method in METHODS:
        for i, h in enumerate(STEPS):
            order = "" if i == 0 else number(np.log2(error[method, STEPS[i - 1]] / error[method, h]))
            rows.append([method, f"1/{round(1 / h)}", runs[method, h][1], error[method, h], order])
    timing_rows = [[method, f"1/{round(1 / h)}", f"{runs[method, h][2] * 1e3:.3g}",
                    f"{runs[method, h][2] / runs[method, h][1] * 1e6:.3g}"] for method in METHODS for h in STEPS]
    return Section(
        "Positions are not predicted per frame: they are integrated from the canonical state through "
        "the velocity field, `dx/dt = v(x, t)`, with a fixed-step explicit scheme. The test problem "
        "here is the rigid rotation `v = ω × x` about z at ω = 2π, whose exact solution is the unit "
        "circle, back at the start at t = 1. Euler, midpoint RK2 and classic RK4 use 1, 2 and 4 "
        "evaluations of the field per step and have global errors of order 1, 2 and 4 in the step "
        "h: once h is small enough, halving it divides the error by about 2, 4 and 16 (the `order` "
        "column is log2 of that ratio).",
        [session({"y0": y0, "w": w}, "f = lambda y, t: velocity(y, w)  # v = ω × x",
                 *[step for method in METHODS for step in (
                     f"integrate(f, y0, t0=0, t1=1, h=1/8, method={method!r})",
                     {f"y1 ({method})": runs[method, FIGURE_STEP][0]})]),
         table(["method", "h", "f evaluations", "error at t = 1", "order"], rows),
         _trajectory_figure(figures, f, y0, error),
         "**What accuracy costs.** The work is the number of field evaluations: steps × stages. For the "
         "same work, a higher-order method is far more accurate here: RK4 with h = 1/32 (128 "
         f"evaluations) is off by {number(error['rk4', 1 / 32])}, Euler with h = 1/128 (128 evaluations) by "
         f"{number(error['euler', 1 / 128])}. Wall times of the NumPy reference, best of {TIMING_REPEATS} runs, one "
         "particle (so mostly Python overhead per evaluation; the fast path batches particles):",
         timings(table(["method", "h", "wall time (ms)", "per evaluation (µs)"], timing_rows)),
         _cost_figure(figures, runs, error)],
    )


def _solve_all(f, calls, y0):
    """(method, h) -> (y(1) (3,), field evaluations, best wall time in s) of integrate from 0 to 1 for
    every method and step; `calls` is the one-element counter that `f` increments."""
    runs = {}
    for method in METHODS:
        for h in STEPS:
            walls = []
            for _ in range(TIMING_REPEATS):
                calls[0] = 0
                start = time.perf_counter()
                y1 = integrate(f, y0, 0.0, 1.0, h, method)
                walls.append(time.perf_counter() - start)
            runs[method, h] = (y1[0], calls[0], min(walls))
    return runs


def _trajectory_figure(figures, f, y0, error):
    fig = new_figure(10, 4.2)
    ax_path, ax_error = fig.subplots(1, 2)
    angle = np.linspace(0, 2 * np.pi, 200)
    ax_path.plot(np.cos(angle), np.sin(angle), color="k", linewidth=2, label="exact: unit circle")
    times = np.linspace(0, 1, round(1 / FIGURE_STEP) + 1)
    for method in METHODS:
        # Each point integrates from 0 to t with h = 1/8, so the points are the method's own steps.
        path = np.stack([integrate(f, y0, 0.0, t, FIGURE_STEP, method)[0] for t in times])
        ax_path.plot(path[:, 0], path[:, 1], "o-", color=METHOD_COLOURS[method], markersize=3, label=method)
    ax_path.set(aspect="equal", xlabel="x", ylabel="y", title=f"one turn with h = 1/{round(1 / FIGURE_STEP)}")
    ax_path.legend(fontsize=8, loc="upper right")
    for order, method in zip((1, 2, 4), METHODS):
        errors = [error[method, h] for h in STEPS]
        ax_error.loglog(STEPS, errors, "o-", color=METHOD_COLOURS[method], label=method)
        ax_error.loglog(STEPS, errors[-1] * (np.array(STEPS) / STEPS[-1]) ** order, ":",
                        color=METHOD_COLOURS[method], label=f"slope {order}")
    ax_error.set(xlabel="step h", ylabel="|x(1) − x_exact(1)|", title="global error against step size")
    ax_error.legend(fontsize=7, ncol=2)
    return save(fig, figures, "integ-circle",
                "integrate on the rigid rotation: trajectories against the exact circle (Euler spirals outward, "
                "RK2 drifts, RK4 stays on it), and the error at t = 1 against h on log axes with the slopes "
                "of orders 1, 2 and 4.")


def _cost_figure(figures, runs, error):
    fig = new_figure(10, 3.6)
    ax_work, ax_time = fig.subplots(1, 2)
    for method in METHODS:
        evaluations = [runs[method, h][1] for h in STEPS]
        walls = [runs[method, h][2] for h in STEPS]
        errors = [error[method, h] for h in STEPS]
        ax_work.loglog(evaluations, errors, "o-", color=METHOD_COLOURS[method], label=method)
        ax_time.loglog(walls, errors, "o-", color=METHOD_COLOURS[method], label=method)
    ax_work.set(xlabel="field evaluations", ylabel="error at t = 1", title="error against work")
    ax_time.set(xlabel="wall time (s), machine-dependent", title="error against wall time (NumPy reference)")
    ax_work.legend(fontsize=8)
    return save(fig, figures, "integ-cost",
                "What accuracy costs: error against the number of field evaluations (left) and against the "
                "measured wall time (right). The wall times depend on the machine and are not part of the "
                "regeneration check; the shape of the curves is what carries over.")


def rotscale_section(figures):
    """VG-ROTSCALE: spin plus stretch acting on Gaussians turned 0°, 45° and 90° about z."""
    q = np.stack([axis_angle_quat([0, 0, 1], 0), axis_angle_quat([0, 0, 1], 45), axis_angle_quat([0, 0, 1], 90)])
    w = np.tile(coefficient_vector(rotation=(0, 0, 1), stretch=(0.5, 0, -0.5)), (3, 1))
    q_dot, log_s_dot = rotscale_rates(q, w)
    return Section(
        "A Gaussian is a small blob of material, so the field that moves its centre should also turn "
        "and deform it. The velocity gradient `∇v = A(w)` splits into a spin (antisymmetric part), "
        "which turns the quaternion, and a rate of strain (symmetric part), which stretches each "
        "principal axis by the strain rate along it. The example spins about z at 1 rad per unit time "
        "while stretching x (+0.5) and squeezing z (−0.5), for a Gaussian aligned with the world "
        "axes, one turned 45° and one turned 90° about z: the x-stretch moves from its first axis to "
        "its second as it turns, the spin's `q̇` is the same rotation rate for all three.",
        [session({"q": q, "w[0]": w[0]}, "q_dot, log_s_dot = rotscale_rates(q, w)",
                 {"q_dot": q_dot, "log_s_dot": log_s_dot})],
    )


def trajectory_section(figures):
    """VG-TRAJ: base states after a rigid quarter turn and after a stretch, with exact answers."""
    x0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.5, 0.2]])
    q0 = np.tile(axis_angle_quat([0, 0, 1], 0), (2, 1))
    s0 = np.array([[0.2, 0.1, 0.1], [0.1, 0.1, 0.1]])
    rigid = constant_motion_params(coefficient_vector(rotation=(0, 0, np.pi / 2)))
    stretch = constant_motion_params(coefficient_vector(stretch=(np.log(2), 0, -np.log(2))))
    steps = []
    for name, params, exact in (
            ("a quarter turn about z", rigid, "x rotated by 90° about z, q = 90° about z, s unchanged"),
            ("stretch x by 2, squeeze z by 2", stretch, "x and s scaled by (2, 1, 0.5), q unchanged")):
        z = physics_code(params, x0, CFG)
        x, q, s = base_state(params, x0, q0, s0, z, 1.0, 1 / 16, "rk4", CFG)
        steps += [f"# {name} over t in [0, 1]; exact: {exact}",
                  "x_t, q_t, s_t = base_state(params, x0, q0, s0, z, t=1, h=1/16, method='rk4', cfg)",
                  {"x_t": x, "q_t": q, "s_t": s}]
    return Section(
        "The base state of every Gaussian at time t integrates position, orientation and log-scale "
        "together from t = 0 (VG-INTEG on the rates of VG-VEL and VG-ROTSCALE), with the code frozen "
        "at the particle's canonical value. Scales are integrated in log space so they stay "
        "positive. The examples use coefficients that are constant in time, so the exact answers are "
        "known: a rigid quarter turn, and a stretch by a factor 2 along x with a squeeze by 2 along z.",
        [session({"x0": x0, "q0": q0, "s0": s0}, *steps), _trajectory_states_figure(figures)],
    )


def _trajectory_states_figure(figures):
    x0 = np.array([[0.8, 0.0, 0.0], [0.0, 0.5, 0.0], [-0.4, -0.4, 0.0]])
    q0 = np.stack([axis_angle_quat([0, 0, 1], a) for a in (0, 60, -30)])
    s0 = np.array([[0.2, 0.06, 0.06], [0.15, 0.08, 0.08], [0.12, 0.12, 0.05]])
    fields = (("rigid: spin about z", coefficient_vector(rotation=(0, 0, np.pi / 2))),
              ("spin about z + stretch in x", coefficient_vector(rotation=(0, 0, np.pi / 2), stretch=(0.6, 0, 0))))
    times = np.linspace(0, 1, 5)
    fig = new_figure(10, 4.6)
    for ax, (title, w) in zip(fig.subplots(1, 2), fields):
        params = constant_motion_params(w)
        z = physics_code(params, x0, CFG)
        for k, t in enumerate(times):
            x, q, s = base_state(params, x0, q0, s0, z, t, 1 / 16, "rk4", CFG)
            Sigma = covariance_3d(q, s)
            for g in range(len(x0)):
                covariance_ellipse(ax, x[g, :2], Sigma[g, :2, :2], 2.0, color=f"C{g}", alpha=0.3 + 0.7 * k / 4)
            ax.plot(x[:, 0], x[:, 1], "k.", markersize=3)
        ax.set(title=title, aspect="equal", xlim=(-1.5, 1.5), ylim=(-1.5, 1.5), xlabel="x", ylabel="y")
    return save(fig, figures, "traj-states",
                "base_state of three Gaussians (2σ ellipses, top view) at t = 0, 0.25, ..., 1 (fainter is "
                "earlier): in a rigid spin they turn with the body and keep their shape; with a stretch "
                "along x added they also grow along the axis that currently points along x.")


SECTIONS = {"VG-INTEG": integration_section, "VG-ROTSCALE": rotscale_section, "VG-TRAJ": trajectory_section}
