"""The learned motion of each moving body's centre against the truth, over time.

A diagnostic of the error budget (benchmarks/FIDELITY.md, "Where toss's future error comes
from"): for a run trained on a generated scene, the velocity the model gives the material
point at each moving body's centre (`model.particle_velocity` along the true path), minus
the true velocity, at each of `times`; the spin there (the antisymmetric part of the
velocity gradient, by central differences of that same particle velocity, which is affine in
the position at a frozen code); and the centre's mean acceleration inside the window and past
it (differences of those velocities), each against the same quantity of the truth. An error
that every seed shares shows here as the same vector run after run, where the noise of
training would scatter it. With rigid motion patterns (VG-COEF-RIGID) it also gives how far
each body's pattern has put its centre from the axis through the body's true centre.

Regenerate: velogauss diagnose centre RUN_DIR [RUN_DIR ...] [--data SCENE_DIR] [--times 0,0.375,0.75,1]
(`--data`: the generated scene when it is not RUN_DIR/data, e.g. a fidelity run's
CACHE/data/SCENE.)
"""

from pathlib import Path

import numpy as np
import torch

from velogauss.evaluate import query
from velogauss.scenes import load_ground_truth
from velogauss.scenes.trajectories import StaticMotion
from velogauss.train.checkpoint import load_model
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import mixing_weights

DEFAULT_TIMES = (0.0, 0.375, 0.75, 1.0)
# Half the central-difference step of the velocity gradient (world units): the particle velocity
# is affine in x at a frozen code, so a step near the bodies' size only keeps rounding small.
GRADIENT_STEP = 0.1


def centre_errors(model, scene, times=DEFAULT_TIMES):
    """{body name: [(t, error (3,), |true velocity|)]} for each moving body of `scene` (an
    `AnalyticScene`) under `model` (a `VeloGaussModel`).

    error = learned − true velocity of the material point at the body's centre at t = 0,
    taken along its true path.
    """
    return {name: [(t, learned - truth, float(np.linalg.norm(truth))) for t, learned, truth in rows]
            for name, rows in _centre_velocities(model, scene, times).items()}


def centre_motion(model, scene, max_time, horizon=1.0):
    """{body name: {"spin": (learned (3,), true (3,)), "acc_window": (learned, true),
    "acc_future": (learned, true)}} for each moving body: the spin (axial vector of the
    velocity gradient's antisymmetric part, rad per unit time) at the centre's material point
    at `max_time`, and the centre's mean acceleration over [0, max_time] and over
    [max_time, horizon] (differences of its velocities along the true path)."""
    times = (0.0, float(max_time), float(horizon))
    out = {}
    for body, rows in zip(_moving_bodies(scene), _centre_velocities(model, scene, times).values()):
        (_, l0, v0), (_, l1, v1), (_, l2, v2) = rows
        c0 = np.asarray(body.centre, dtype=np.float64)[None]
        c = scene.position(c0, max_time, margin=np.inf)
        learned = _spin(lambda x: query(model.particle_velocity, max_time, x, start=np.repeat(c0, len(x), 0)), c)
        truth = _spin(lambda x: scene.velocity(x, max_time, margin=np.inf), c)
        out[body.name] = {"spin": (learned, truth),
                          "acc_window": ((l1 - l0) / max_time, (v1 - v0) / max_time),
                          "acc_future": ((l2 - l1) / (horizon - max_time), (v2 - v1) / (horizon - max_time))}
    return out


def reference_offsets(model, scene):
    """{body name: [(knot time τ, |e_perp(τ)|)]} for a model with rigid motion patterns
    (VG-COEF-RIGID): e(τ) = c_k(τ) − c(τ), the pattern's centre at its knot minus the body's
    true centre, with the component along the pattern's spin axis removed (any point on the
    axis gives the same field); k is the pattern with the largest mixing weight at the
    material point of the body's centre. 0 when the knots follow the body's centre; a centre
    that follows another material point of the body is off by that point's distance from
    the axis through the centre. Raises ValueError for other pattern forms."""
    spec = model.spec
    if not spec.rigid_patterns:
        raise ValueError("model: reference offsets need rigid motion patterns (model.patterns = 'rigid')")
    n = spec.rigid_knots
    knot_times = [spec.max_time * i / (n - 1) for i in range(n)]
    params = model.motion.params()
    out = {}
    with torch.no_grad():
        for body in _moving_bodies(scene):
            c0 = np.asarray(body.centre, dtype=np.float64)[None]
            z = physics_code(params, torch.as_tensor(c0, dtype=model.gaussians.means.dtype), spec)
            k = int(mixing_weights(params, z)[0].argmax())
            row = params["time"][k].detach().cpu().numpy().astype(np.float64)
            axis = row[:3] / max(np.linalg.norm(row[:3]), np.finfo(np.float64).tiny)
            rows = []
            for i, tau in enumerate(knot_times):
                e = row[3 + 3 * i: 6 + 3 * i] - scene.position(c0, tau, margin=np.inf)[0]
                rows.append((tau, float(np.linalg.norm(e - axis * (e @ axis)))))
            out[body.name] = rows
    return out


def _moving_bodies(scene):
    return [body for body in scene.bodies if not isinstance(body.motion, StaticMotion)]


def _centre_velocities(model, scene, times):
    """{body name: [(t, learned velocity (3,), true velocity (3,))]} at the centre's material point."""
    out = {}
    with torch.no_grad():
        for body in _moving_bodies(scene):
            c0 = np.asarray(body.centre, dtype=np.float64)[None]
            rows = []
            for t in times:
                c = scene.position(c0, t, margin=np.inf)
                truth = scene.velocity(c, t, margin=np.inf)[0]
                learned = query(model.particle_velocity, t, c, start=c0)[0]
                rows.append((float(t), learned, truth))
            out[body.name] = rows
    return out


def _spin(velocity, x):
    """Axial vector (3,) of the antisymmetric part of the gradient of `velocity` ((M, 3) -> (M, 3))
    at the point x (1, 3), by central differences."""
    steps = GRADIENT_STEP * np.eye(3)
    grad = (velocity(x + steps) - velocity(x - steps)).T / (2 * GRADIENT_STEP)  # [i, j] = dv_i / dx_j
    return 0.5 * np.array([grad[2, 1] - grad[1, 2], grad[0, 2] - grad[2, 0], grad[1, 0] - grad[0, 1]])


def report(run_dir, data_dir=None, times=DEFAULT_TIMES):
    """The diagnostic of one trained run, line by line: per moving body, the velocity error at
    each of `times`, the spin and the two mean accelerations against the truth, and (rigid
    patterns only) the knots' offset from the axis through the true centre. `data_dir`: the
    generated scene (default RUN_DIR/data)."""
    fmt = lambda v: np.array2string(np.asarray(v), precision=3, sign="+")  # noqa: E731
    model, cfg = load_model(run_dir)
    scene = load_ground_truth(Path(run_dir) / "data" if data_dir is None else data_dir)
    motion = centre_motion(model, scene, cfg.data.max_time)
    offsets = reference_offsets(model, scene) if model.spec.rigid_patterns else {}
    for name, rows in centre_errors(model, scene, times).items():
        # |error| beside the true speed, not their ratio: a centre spinning in place is at rest.
        cells = "  ".join(f"t={t:g}: {fmt(err)} (|error| {np.linalg.norm(err):.3f} at speed {speed:.3f})"
                          for t, err, speed in rows)
        yield f"{run_dir} [{name}] velocity error  {cells}"
        for key, (learned, truth) in motion[name].items():
            yield f"{run_dir} [{name}] {key}: learned {fmt(learned)}, true {fmt(truth)}, error {fmt(learned - truth)}"
        if name in offsets:
            cells = "  ".join(f"t={tau:g}: {offset:.3f}" for tau, offset in offsets[name])
            yield f"{run_dir} [{name}] rigid centre's offset from the axis through the true centre  {cells}"
