"""How far each moving body's Gaussians slip from the material they started on, and how far
their best rigid motion turns against the body's.

A diagnostic of the error budget (benchmarks/FIDELITY.md, section 0z): the Gaussians
of a body are those the trajectory metric tracks (`velogauss.evaluate.trajectory_error`: opacity
at least `ALPHA_MIN`, within `EVAL_SURFACE_MARGIN` of the body at t = 0), each followed along
its physics trajectory (`tracked_positions`). At each time t it gives
- the body's turn: the angle of the rotation that best carries the Gaussians' true material
  points from t = 0 to t (Kabsch; the body's own rotation when it is rigid);
- the Gaussians' turn: the same fit to where the model puts them at t;
- the angle between those two rotations;
- the slip: the Gaussians' mean distance at t from their true material points, over the
  material's mean displacement since t = 0;
- the non-rigid part: the Gaussians' mean distance from their own best rigid motion, over the
  same displacement.

The images fix where a surface is, not which material sits on it: on a face of even colour the
Gaussians can roll round the body and still render it right. Slip that the non-rigid part
does not explain is a rigid motion that turns too slowly or too fast; a large non-rigid part
is Gaussians that drift over the surface.

Regenerate: velogauss diagnose slip RUN_DIR [RUN_DIR ...] [--data SCENE_DIR] [--times 0.25,0.5,0.75,1]
"""

from pathlib import Path

import numpy as np
from velogauss.evaluate import query
from velogauss.scenes import load_ground_truth
from velogauss.scenes.trajectories import StaticMotion
from velogauss.train.checkpoint import load_model
from velogauss_core.constants import ALPHA_MIN, EVAL_SURFACE_MARGIN

DEFAULT_TIMES = (0.25, 0.5, 0.75, 1.0)


def best_rotation(start, end):
    """(R (3, 3), b (3,)): the rotation and translation minimising Σ‖R start_i + b − end_i‖²
    (Kabsch, proper rotations only) for start, end (M, 3), M ≥ 3."""
    a, c = start.mean(axis=0), end.mean(axis=0)
    u, _, vt = np.linalg.svd((start - a).T @ (end - c))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, c - rotation @ a


def angle(rotation):
    """The angle (degrees, in [0, 180]) of a rotation matrix (3, 3)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))))


def body_gaussians(scene, means, opacities):
    """{body index: indices (M,) of the Gaussians of each moving body of `scene`}: those at
    `means (N, 3)` at t = 0 with `opacities (N,)` of at least ALPHA_MIN within EVAL_SURFACE_MARGIN
    of the body; a body with fewer than 3 is left out (a rotation needs 3 points)."""
    owner = scene.body_index(means, 0.0, margin=EVAL_SURFACE_MARGIN)
    out = {}
    for k, body in enumerate(scene.bodies):
        if isinstance(body.motion, StaticMotion):
            continue
        index = np.flatnonzero((owner == k) & (opacities >= ALPHA_MIN))
        if len(index) >= 3:
            out[k] = index
    return out


def slip_rows(scene, means0, positions, groups, times=DEFAULT_TIMES):
    """[{"body", "time", "points", "true_turn", "model_turn", "turn_error", "slip", "nonrigid"}] for
    each body of `groups` ({body index: Gaussian indices}, `body_gaussians`) at each of `times`.

    scene: an `AnalyticScene`; means0 (N, 3): the Gaussians at t = 0; positions: t -> (N, 3), where
    the model puts them at t. Angles in degrees; slip and nonrigid over the material's mean
    displacement since t = 0 (None where it does not move)."""
    rows = []
    for t in times:
        x = np.asarray(positions(float(t)), dtype=np.float64)
        for k, index in groups.items():
            start = means0[index]
            truth = scene.position(start, float(t), margin=np.inf)
            model = x[index]
            r_true, _ = best_rotation(start, truth)
            r_model, b_model = best_rotation(start, model)
            moved = float(np.linalg.norm(truth - start, axis=1).mean())
            scale = moved if moved > 0 else None
            slip = float(np.linalg.norm(model - truth, axis=1).mean())
            nonrigid = float(np.linalg.norm(model - (start @ r_model.T + b_model), axis=1).mean())
            rows.append({"body": scene.bodies[k].name, "time": float(t), "points": int(len(index)),
                         "true_turn": angle(r_true), "model_turn": angle(r_model),
                         "turn_error": angle(r_model @ r_true.T),
                         "slip": None if scale is None else slip / scale,
                         "nonrigid": None if scale is None else nonrigid / scale})
    return rows


TABLE_HEADER = ("| run | body | t | Gaussians | body's turn ° | Gaussians' turn ° | turn error ° | slip | non-rigid |\n"
                "|---|---|---:|---:|---:|---:|---:|---:|---:|")


def table_rows(run_dir, data_dir=None, times=DEFAULT_TIMES):
    """The rows of the diagnostic's markdown table (under TABLE_HEADER) for one trained run.
    `data_dir`: the generated scene (default RUN_DIR/data)."""
    fmt = lambda v: "—" if v is None else f"{v:.3f}"  # noqa: E731
    model, _ = load_model(run_dir)
    scene = load_ground_truth(Path(run_dir) / "data" if data_dir is None else data_dir)
    means0 = query(model.tracked_positions, 0.0)
    opacities = query(lambda t: model.render_inputs_at(t)["opacities"], 0.0).reshape(-1)
    groups = body_gaussians(scene, means0, opacities)
    rows = slip_rows(scene, means0, lambda t: query(model.tracked_positions, t), groups, times)
    for row in rows:
        yield (f"| {run_dir} | {row['body']} | {row['time']:g} | {row['points']} | {row['true_turn']:.1f} | "
               f"{row['model_turn']:.1f} | {row['turn_error']:.1f} | {fmt(row['slip'])} | {fmt(row['nonrigid'])} |")
