"""The velocity error where the training cameras see the surface, and where none does.

A diagnostic of the error budget (benchmarks/FIDELITY.md, "Seen and unseen"): the evaluation's
surface points (`velogauss.evaluate.moving_surface_points`) are split by whether any
training frame sees the material point, and the particle velocity error of
`velogauss.evaluate.velocity_error` is taken over each part, for every moving body and for
all of them. A material point is seen when, in some training frame (its camera at its time,
both inside the observed window), it projects inside the image and the first surface the
ray from the camera centre meets is the point itself (the analytic ray-caster,
`velogauss.scenes.raycast.cast_rays`). Pixels see only what the photometric loss can fit:
an error that sits on the unseen part comes from what the model does between the Gaussians
the images place, not from the images.

Regenerate: velogauss diagnose visibility RUN_DIR [RUN_DIR ...] [--data SCENE_DIR]
(`--data`: the generated scene when it is not RUN_DIR/data, e.g. a fidelity run's
CACHE/data/SCENE.)
"""

from pathlib import Path

import numpy as np

from velogauss.data.dnerf import load_scene
from velogauss.evaluate import moving_surface_points, velocity_error
from velogauss.scenes import load_ground_truth
from velogauss.scenes.raycast import cast_rays
from velogauss.train.checkpoint import load_model
from velogauss_core.constants import NEAR_PLANE, VISIBILITY_TOLERANCE


def seen_points(scene, frames, x0):
    """bool (M,): whether some frame of `frames` (`velogauss.data.dnerf.Frame`) sees the
    material point that starts at `x0 (M, 3)` (on a surface of `scene`, an `AnalyticScene`)
    at the frame's time: in front of the near plane, inside the image (pixel centres at
    +0.5, so the image spans [0, W) × [0, H)), and first along the ray from the camera
    centre up to `VISIBILITY_TOLERANCE` of its distance."""
    x0 = np.asarray(x0, dtype=np.float64)
    seen = np.zeros(len(x0), dtype=bool)
    for frame in frames:
        camera = frame.camera
        x = scene.position(x0, frame.time, margin=np.inf)
        p = x @ camera.viewmat[:3, :3].T + camera.viewmat[:3, 3]
        front = p[:, 2] > NEAR_PLANE
        uv = p[:, :2] / np.where(front, p[:, 2], 1.0)[:, None] * np.diag(camera.K)[:2] + camera.K[:2, 2]
        inside = front & (uv >= 0).all(axis=1) & (uv[:, 0] < camera.width) & (uv[:, 1] < camera.height)
        if not inside.any():
            continue
        offset = x[inside] - camera.centre
        distance = np.linalg.norm(offset, axis=1)
        hits = cast_rays(scene.bodies, np.broadcast_to(camera.centre, offset.shape), offset / distance[:, None],
                         frame.time)
        seen[np.flatnonzero(inside)[hits.distance >= distance * (1.0 - VISIBILITY_TOLERANCE)]] = True
    return seen


def split_velocity_errors(model, scene, frames, max_time):
    """[{"body", "part", "points", "observed", "future"}]: the particle velocity's relative L2
    error (`velocity_error`'s "relative_l2" means over the observed and the future times) of
    `model` on the evaluation's surface points of each moving body of `scene` and of all of
    them ("body": a name, or "all"), over the points `frames` see ("part": "seen") and those
    they do not ("unseen"); a part without points is left out."""
    x0 = moving_surface_points(scene)
    seen = seen_points(scene, frames, x0)
    owner = scene.body_index(x0, 0.0, margin=np.inf)
    groups = [(scene.bodies[k].name, owner == k) for k in np.unique(owner)] + [("all", np.ones(len(x0), bool))]
    rows = []
    for name, member in groups:
        for part, mask in (("seen", seen), ("unseen", ~seen)):
            points = x0[member & mask]
            if len(points) == 0:
                continue
            err = velocity_error(model, scene, max_time, points=points)
            rows.append({"body": name, "part": part, "points": len(points),
                         "observed": err["observed"]["relative_l2"], "future": err["future"]["relative_l2"]})
    return rows


TABLE_HEADER = "| run | body | part | points | vel. err obs | vel. err fut |\n|---|---|---|---:|---:|---:|"


def table_rows(run_dir, data_dir=None):
    """The rows of the diagnostic's markdown table (under TABLE_HEADER) for one trained run:
    `split_velocity_errors` over its training frames. `data_dir`: the generated scene (default
    RUN_DIR/data)."""
    fmt = lambda v: "—" if v is None else f"{v:.3f}"  # noqa: E731
    model, cfg = load_model(run_dir)
    data_dir = Path(run_dir) / "data" if data_dir is None else Path(data_dir)
    frames = load_scene(data_dir, max_time=cfg.data.max_time, half_res=cfg.data.half_res, split=cfg.data.split).train
    for row in split_velocity_errors(model, load_ground_truth(data_dir), frames, cfg.data.max_time):
        yield (f"| {run_dir} | {row['body']} | {row['part']} | {row['points']} | {fmt(row['observed'])} | "
               f"{fmt(row['future'])} |")
