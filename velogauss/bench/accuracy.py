"""Integrator benchmark: what accuracy costs in time, for Euler, RK2 and RK4 (VG-INTEG, VG-TRAJ).

`velogauss_fast.motion.trajectory.base_state` integrates particles from t = 0 to t = 1 with
each method and a range of step sizes h, on motions whose exact solution is known, and the
largest position and rotation-angle errors are set against the wall time of the integration
(forward, and forward + backward as in training).

The motions are the synthetic scenes' own bodies (`velogauss.scenes.catalog`) with motion
parameters built so that every particle's coefficients are exactly the body's
`basis_coefficients(t)` (VG-BASIS) -- only the integrator errs:

* spin -- the `spin` scene's box, turning at 3 rad per unit time about a tilted axis
  through the origin: v = omega x x, constant coefficients;
* toss -- the `toss` scene's throw (launch point, velocity and gravity of the catalog) with
  its spin turned to the vertical axis (same rate). The catalog's tilted spin
  makes the translation coefficients quadratic in t, b(t) = ... - 1/2 (omega x g) t^2,
  and the time network (VG-COEF: an MLP of raw t with silu activations, which grows at most
  linearly) cannot represent t^2 exactly; with omega parallel to gravity omega x g = 0 and
  b(t) is affine in t, which it represents exactly (`linear_in_time_params`).

Exact solutions: positions from `RigidMotion.position`, orientations R(omega t) R(q0).
Errors are measured in float64, so they are the integrators' own; the times are those of
float32, the training dtype (whose rounding floor is shown too). The column mask is each
scene's effects (`velogauss.model.spec`): translation + rotation for both.

Regenerate: velogauss bench accuracy
Smoke test: velogauss bench accuracy --quick --out /tmp/bench.md
"""

import json
import math
import statistics
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from matplotlib.figure import Figure
from scipy.spatial.transform import Rotation

from velogauss.bench.harness import machine, regenerate_command, timed_passes, write_section
from velogauss.bench.motion import leaves
from velogauss.config import ModelConfig
from velogauss.io_utils import save_figure
from velogauss.model.spec import resolve_motion_spec
from velogauss.scenes.catalog import SCENES
from velogauss.scenes.trajectories import RigidMotion
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.params import params_to_torch
from velogauss_fast.motion.trajectory import base_state
from velogauss_core.motion import COLUMN_GROUPS, init_motion_params, MotionSpec

SECTION = "## Integrator accuracy vs time"
COMMAND = "velogauss bench accuracy"
PLOT_NAME = "accuracy_vs_time.png"
ORDERS = {"euler": 1, "rk2": 2, "rk4": 4}
# Euler's angle error is second order under a constant spin: its first-order error only scales
# q, which base_state's normalisation removes.
ANGLE_ORDERS = {**ORDERS, "euler": 2}
T_END = 1.0
DEFAULT = (ModelConfig.integrator, ModelConfig.step)  # what training integrates with


class Sizes(NamedTuple):
    n_particles: int
    steps: tuple  # h, largest first; each half the one before
    repeats: int  # timed passes per (method, h), after one warm-up of the first


FULL = Sizes(20_000, (0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625, 0.003125), 3)
# For smoke tests: h small enough (|omega| h <= 0.2) that the error ratios show the orders.
QUICK = Sizes(64, (0.05, 0.025, 0.0125), 1)


class Case(NamedTuple):
    """A scene body with an exactly representable motion: name, motion, the body's box
    (centre (3,), half-sizes (3,), rotation (3, 3)) the particles fill, and its column mask."""

    name: str
    motion: RigidMotion
    centre: np.ndarray
    size: np.ndarray
    rotation: np.ndarray
    mask: tuple


def cases():
    """The spin and toss cases (see the module docstring), from the scene catalog."""
    out = []
    for name in ("spin", "toss"):
        scene = SCENES[name]()
        body = scene.bodies[0]
        motion = body.motion
        if name == "toss":
            # The spin about the vertical: omega x gravity = 0, so b(t) is affine in t.
            motion = RigidMotion(motion.centre, omega=(0.0, 0.0, float(np.linalg.norm(motion.omega))),
                                 velocity=motion.velocity0, gravity=motion.gravity)
        model_cfg = ModelConfig(effects=tuple(scene.effects), incompressible=scene.incompressible)
        mask = resolve_motion_spec(model_cfg, None, 1.0).mask
        out.append(Case(name, motion, body.centre, body.size, body.rotation, mask))
    return out


def affine_in_time(motion):
    """(w0, w1) (12,) each with motion.basis_coefficients(t) = w0 + w1 t for all t (VG-BASIS).

    Checked at t = 0.25, 0.5 and 0.75 (float64 rounding of the rotations, ~1e-15, times a
    margin); raises ValueError for a motion whose coefficients are not affine in t (the
    catalog's toss, whose tilted spin gives a t^2 term).
    """
    w0 = motion.basis_coefficients(0.0)
    w1 = motion.basis_coefficients(1.0) - w0
    for t in (0.25, 0.5, 0.75):
        gap = np.abs(motion.basis_coefficients(t) - (w0 + w1 * t)).max()
        if gap > 1e-12 * (1.0 + np.abs(w0).max() + np.abs(w1).max()):
            raise ValueError(f"motion: coefficients not affine in t (off by {gap:.2e} at t = {t})")
    return w0, w1


def linear_in_time_params(cfg, w0, w1, rng):
    """A motion parameter dict whose coefficients are w0 + w1 t (12,) for every particle (VG-COEF).

    All K patterns equal P(t) = w0 + w1 t, so any softmax mixture m(z) gives it (up to the
    rounding of sum_k m_k = 1). The time network passes raw t through exactly: neurons 0 and
    1 of the first layer hold t and -t, every further hidden layer maps (a, b) to
    (silu(a - b), silu(b - a)), and since silu(u) - silu(-u) = u (sigmoid(u) + sigmoid(-u) = 1)
    the pair stays (silu(t), silu(-t)); the last layer reads w0 + w1 (silu(t) - silu(-t)).
    Every other weight of the time network is zero; the code and mixing networks are
    `init_motion_params(rng, cfg)`'s. Requires cfg.hidden >= 2.
    """
    params = init_motion_params(rng, cfg)
    K = cfg.n_patterns
    layers = []
    for k, (W, b) in enumerate(params["time"]):
        W, b = np.zeros_like(W), np.zeros_like(b)
        if k == 0:
            W[0, :2] = [1.0, -1.0]  # input 0 of gamma(t) is t itself (VG-ENC)
        elif k < len(params["time"]) - 1:
            W[:2, :2] = [[1.0, -1.0], [-1.0, 1.0]]
        else:
            W[0], W[1], b = np.tile(w1, K), -np.tile(w1, K), np.tile(w0, K)
        layers.append((W, b))
    params["time"] = layers
    return params


def _particles(case, n, rng):
    """x0 uniform in the body's box, random q0 (any norm) and small s0: float64 arrays."""
    u = rng.uniform(-1.0, 1.0, (n, 3)) * case.size
    x0 = case.centre + u @ case.rotation.T
    return x0, rng.standard_normal((n, 4)), rng.uniform(0.005, 0.05, (n, 3))


def exact_state(motion, x0, q0, t):
    """Exact positions (N, 3) and orientations (scipy Rotation) at t of a rigid motion's particles."""
    spin = Rotation.from_rotvec(motion.omega * t)
    return motion.position(x0, t), spin * Rotation.from_quat(q0[:, [1, 2, 3, 0]])  # scipy: scalar last


def state_errors(x, q, x_exact, r_exact):
    """(max |x - x_exact|, max rotation angle between R(q) and r_exact) over the particles.

    The angle comes from the quaternion of R(q) R_exact^T (scipy's magnitude, 2 atan2(|v|, |w|)),
    accurate for small angles where arccos of the trace would lose half the digits.
    """
    position = float(np.linalg.norm(x - x_exact, axis=1).max())
    angle = float((Rotation.from_quat(q[:, [1, 2, 3, 0]]) * r_exact.inv()).magnitude().max())
    return position, angle


class Problem(NamedTuple):
    """One case's base_state inputs in one dtype: params, x0, q0, s0, z, cfg."""

    params: dict
    x0: torch.Tensor
    q0: torch.Tensor
    s0: torch.Tensor
    z: torch.Tensor
    cfg: MotionSpec


def problem(case, arrays, dtype, device, requires_grad=False):
    """base_state inputs for `case` from its float64 arrays (params, x0, q0, s0) in `dtype`."""
    cfg = MotionSpec(mask=case.mask)
    params_np, x0, q0, s0 = arrays
    params = params_to_torch(params_np, dtype, device, requires_grad)
    x0, q0, s0 = (torch.tensor(a, dtype=dtype, device=device, requires_grad=requires_grad) for a in (x0, q0, s0))
    with torch.no_grad():
        z = physics_code(params, x0, cfg)
    return Problem(params, x0, q0, s0, z, cfg)


def _integrate(p, method, h):
    return base_state(p.params, p.x0, p.q0, p.s0, p.z, T_END, h, method, p.cfg)


def _errors(p, method, h, exact):
    with torch.no_grad():
        x, q, _ = _integrate(p, method, h)
    return state_errors(x.double().cpu().numpy(), q.double().cpu().numpy(), *exact)


def _timings(p, method, h, repeats, device):
    """(median forward seconds, median forward + backward seconds) of base_state on p.

    Forward under no_grad; backward of <out, c> for a fixed random cotangent c, to every
    motion parameter and to x0, q0, s0, as training does.
    """
    tensors = leaves(p.params) + [p.x0, p.q0, p.s0]
    g = torch.Generator().manual_seed(0)
    cot = [torch.randn(p.x0.shape[0], k, generator=g).to(device=device, dtype=p.x0.dtype) for k in (3, 4, 3)]

    def sync():
        if device != "cpu":
            torch.cuda.synchronize()

    def forward():
        with torch.no_grad():
            _integrate(p, method, h)
        sync()

    def forward_backward():
        for leaf in tensors:
            leaf.grad = None
        sum((o * c).sum() for o, c in zip(_integrate(p, method, h), cot)).backward()
        sync()

    return tuple(statistics.median(timed_passes(fn, repeats)) for fn in (forward, forward_backward))


def observed_orders(results, steps, key):
    """Per method, the least-squares slope of log(error) against log(h) over `steps` (errors
    results[(method, h)][key]): the observed convergence order."""
    logs_h = np.log(steps)
    return {m: float(np.polyfit(logs_h, np.log([results[(m, h)][key] for h in steps]), 1)[0]) for m in ORDERS}


def measure(sizes, device="cpu", echo=print):
    """Errors and timings for every (method, h) of `sizes`: {(method, h): result dict}."""
    rng = np.random.default_rng(0)
    setups = []
    for case in cases():
        w0, w1 = affine_in_time(case.motion)
        params = linear_in_time_params(MotionSpec(mask=case.mask), w0, w1, rng)
        arrays = (params, *_particles(case, sizes.n_particles, rng))
        exact = exact_state(case.motion, arrays[1], arrays[2], T_END)
        setups.append((case, problem(case, arrays, torch.float64, device), exact, arrays))
    toss, _, toss_exact, toss_arrays = setups[-1]
    timed = problem(toss, toss_arrays, torch.float32, device, requires_grad=True)
    _timings(timed, "rk2", sizes.steps[0], 1, device)  # warm-up: lazy inits, allocator
    results = {}
    for method in ORDERS:
        for h in sizes.steps:
            r = {"method": method, "h": h, "steps": max(1, math.ceil(T_END / h))}
            for case, p64, exact, _ in setups:
                r[f"{case.name}_position"], r[f"{case.name}_angle"] = _errors(p64, method, h, exact)
            r["toss_position_float32"], _ = _errors(timed, method, h, toss_exact)
            r["forward_s"], r["forward_backward_s"] = _timings(timed, method, h, sizes.repeats, device)
            results[(method, h)] = r
            echo(json.dumps(r))
    return results


def _table(results, sizes):
    lines = [
        "| method | h | steps | spin: max position error | spin: max angle error (rad) | toss: max position "
        "error | toss: max angle error (rad) | toss: float32 position error | order (toss position) "
        "| forward (s) | forward + backward (s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for method in ORDERS:
        previous = None
        for h in sizes.steps:
            r = results[(method, h)]
            # The local order log2(e(2h) / e(h)) between this step size and the one before.
            order = "-" if previous is None else f"{math.log2(previous / r['toss_position']):.2f}"
            previous = r["toss_position"]
            mark = " (default)" if (method, h) == DEFAULT else ""
            lines.append(
                f"| {method}{mark} | {h:g} | {r['steps']} | {r['spin_position']:.2e} | {r['spin_angle']:.2e} | "
                f"{r['toss_position']:.2e} | {r['toss_angle']:.2e} | {r['toss_position_float32']:.2e} | {order} | "
                f"{r['forward_s']:.4f} | {r['forward_backward_s']:.4f} |")
    return "\n".join(lines)


def plot(results, sizes, path):
    """Error against forward + backward time, log-log, one line per method, points labelled by h."""
    fig = Figure(figsize=(12, 5))
    orders = {key: observed_orders(results, sizes.steps, key) for key in ("toss_position", "toss_angle")}
    floor = min(r["toss_position_float32"] for r in results.values())
    titles = {"toss_position": "toss: max position error (world units)",
              "toss_angle": "toss: max rotation-angle error (rad)"}
    for k, key in enumerate(titles):
        ax = fig.add_subplot(1, 2, k + 1)
        for method, expected in (ORDERS if key == "toss_position" else ANGLE_ORDERS).items():
            times = [results[(method, h)]["forward_backward_s"] for h in sizes.steps]
            errors = [results[(method, h)][key] for h in sizes.steps]
            ax.loglog(times, errors, "o-", label=f"{method}: observed order {orders[key][method]:.2f} "
                                                 f"(expected {expected})")
            for h, x, y in zip(sizes.steps, times, errors):
                ax.annotate(f"h={h:g}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
        if DEFAULT in results:
            d = results[DEFAULT]
            ax.loglog([d["forward_backward_s"]], [d[key]], "*", color="black", markersize=14,
                      label=f"default: {DEFAULT[0].upper()}, h = {DEFAULT[1]:g}")
        note = None
        if key == "toss_position":
            ax.axhline(floor, color="grey", linestyle=":", label=f"float32 rounding floor ({floor:.1e})")
        else:
            note = ("Euler: 2nd order in angle under a constant spin\n(its 1st-order error only scales q,\n"
                    "which normalisation removes)")
        ax.set_xlabel(f"forward + backward time of base_state, {sizes.n_particles:,} particles, t = 0 to 1 (s)")
        ax.set_title(titles[key] + "\nerror ~ h^p ~ time^-p: orders p = 1, 2, 4 for Euler, RK2, RK4", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="lower left", title=note, title_fontsize=8)
    save_figure(path, fig)


def run(out_path="benchmarks/RESULTS.md", device="cpu", quick=False, threads=None, echo=print):
    """Measure, write the "## Integrator accuracy vs time" section of out_path and the plot
    next to it (PLOT_NAME); returns the results {(method, h): dict}.

    quick: the QUICK sizes (smoke tests); threads: torch CPU threads while measuring (None:
    torch's current setting, which is restored afterwards).
    """
    sizes = QUICK if quick else FULL
    previous = torch.get_num_threads()
    torch.set_num_threads(threads or previous)
    try:
        results = measure(sizes, device, echo)
        machine_line = machine()  # names the threads measured with
    finally:
        torch.set_num_threads(previous)
    plot_path = Path(out_path).parent / PLOT_NAME
    plot(results, sizes, plot_path)
    orders = {key: observed_orders(results, sizes.steps, key) for key in ("toss_position", "spin_position")}
    summary = "; ".join(f"{m}: {orders['toss_position'][m]:.2f} (toss), {orders['spin_position'][m]:.2f} (spin)"
                        for m in ORDERS)
    toss_mask = cases()[-1].mask
    groups = " + ".join(g for g, cols in COLUMN_GROUPS.items() if all(toss_mask[c] for c in cols))
    command = regenerate_command(COMMAND, quick=quick, device=device, threads=threads)
    text = "\n\n".join([
        SECTION,
        f"`base_state` from t = 0 to {T_END:g} for {sizes.n_particles:,} particles per motion, every method "
        f"and step size h (steps = ceil(1 / h)), on two motions of the scene catalog whose exact solution is "
        f"known and which the motion parameters represent exactly (`velogauss.bench.accuracy`): **spin** (the "
        f"`spin` box, 3 rad per unit time about a tilted axis, constant coefficients) and **toss** (the `toss` "
        f"throw under gravity 8, its spin turned vertical so that the coefficients are "
        f"affine in t; the catalog's tilted spin would need a t^2 term the time network cannot represent). "
        f"Errors: largest over the particles of |x - x_exact| (world units; the bodies are ~1 unit) and of the "
        f"angle between R(q) and the exact orientation, computed in float64 so they are the integrator's; the "
        f"float32 column is what training's dtype reaches. Times: float32 on {device.upper()}, median of "
        f"{sizes.repeats} runs after one warm-up, forward under no_grad, backward to every motion parameter and "
        f"x0, q0, s0 (toss's mask: {groups}; `MotionSpec()` sizes). 'order' is log2 of the error ratio "
        f"to the previous h.",
        f"Observed orders (least-squares slope of log position error against log h): {summary}; expected 1, 2, 4. "
        f"Training's default is {DEFAULT[0].upper()} with h = {DEFAULT[1]:g}. Plot: `{PLOT_NAME}`.",
        f"Machine: {machine_line}.",
        f"Regenerate: `{command}`",
        _table(results, sizes),
    ])
    write_section(str(out_path), SECTION, text)
    return results
