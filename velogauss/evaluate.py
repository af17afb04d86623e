"""Evaluate a trained run: image metrics on the interpolation and extrapolation splits, a
"freeze the last observed frame" baseline, and, for synthetic scenes, the error of the
learned motion against the analytic ground truth.

Image metrics (spec/losses_metrics.md): PSNR (VG-METRIC, capped at 100 dB), SSIM
(VG-METRIC-SSIM) and LPIPS v0.1 with the AlexNet and VGG backbones (VG-METRIC-LPIPS), per
frame and as the mean over the split's frames.

Freeze baseline: every extrapolation frame is compared with the model rendered from that
frame's camera at `t = max_time` -- the last observed instant, held still. The gap between
it and the model's own extrapolation is what the learned physics buys.

Motion metrics (only when the scene folder holds a generated `scene.json`; ground truth
from `velogauss.scenes.load_ground_truth`), at the times `MOTION_EVAL_TIMES` (11 evenly
spaced times in [0, 1]; those `> max_time` are the future):

- velocity: `MOTION_EVAL_POINTS` points `x0` are sampled on the surfaces of the bodies at
  t = 0 (`AnalyticScene.sample_surface`, fixed seed) and the samples on bodies that do not
  move (static motion) are dropped. At each time t the points are carried to their true
  positions `x = position(x0, t)` and the model's velocity there is compared with the true
  one: `relative L2 error(t) = ‖v(x, t) − v_gt(x, t)‖ / ‖v_gt(x, t)‖`, norms over all
  points and components (Frobenius); a time where `‖v_gt‖` is at most `EVAL_VELOCITY_FLOOR`
  times its largest value over the times (zero, or a periodic motion's reversal, zero up to
  rounding) has no relative error (None) and is left out of the means. Also reported: the mean per-point
  error `mean_i |v(x_i, t) − v_gt(x_i, t)|` (world units per unit time).
  Two velocities are scored: the particle velocity `particle_velocity(x0, x, t)` (the
  mixing weights frozen at the material point's start, as along a Gaussian's path; keys
  `relative_l2`, `mean_abs`) and the Eulerian field `velocity_at(x, t)` (the weights read at
  x at time t; key `field_relative_l2`). The points are surface points, not Gaussians: with
  the affine velocity both take the weights of their nearest Gaussians (VG-FIELD-GAUSS: at x0
  among the canonical means, at x among the Gaussians' positions at t), as the code network
  at x(t) would read the code of whatever sat at x at t = 0 (`MotionSpec.query_code`).
  Predicting zero velocity gives a relative error of exactly 1. The particle velocity's error
  e = v − v_gt also splits exactly, e = ē + (e − ē), where ē replaces each point's error by
  the mean over its body's points (the two parts are orthogonal, so their squared relative
  errors add up to the whole's): `translation_relative_l2` = ‖ē‖ / ‖v_gt‖, the error of each
  body's mean motion, and `spin_relative_l2` = ‖e − ē‖ / ‖v_gt‖, the rest (its spin and
  change of shape). `translation_only_relative_l2` = ‖v_gt − v̄_gt‖ / ‖v_gt‖ is the scene's
  own: what a model whose every body moved with its true mean velocity, without spin or
  change of shape, would score. A model without a velocity
  field (the "deform-only" ablation) has no velocity to score: every velocity error is None.
- trajectories: the Gaussians whose canonical mean `μ0 = tracked_positions(0)` lies inside
  or within `EVAL_SURFACE_MARGIN` (world units) of a moving body at t = 0 and whose opacity
  is at least `ALPHA_MIN` (lower opacities never reach a pixel, VG-ALPHA) are followed:
  `error(t) = mean_i |tracked_positions(t)_i − position(μ0_i, t)|` (world units): with a
  velocity field the physics-only trajectory x*(t) (VG-TRAJ, without the auxiliary deformation) against the true
  path of the material point at `μ0`. Reported next to it: `mean_i |position(μ0_i, t) − μ0_i|`,
  the error a model that does not move at all would have. A model without a velocity field
  has no physics trajectory; its rendered means (canonical plus deformation) are followed
  instead (`VeloGaussModel.tracked_positions`).

Means are taken over the observed times (`t ≤ max_time`), the future times and all times.
"""

import numpy as np
import torch
from tqdm.auto import tqdm

from velogauss.io_utils import to_numpy
from velogauss.scenes.trajectories import StaticMotion
from velogauss_fast import metrics
from velogauss_core.constants import ALPHA_MIN, EVAL_SURFACE_MARGIN, EVAL_VELOCITY_FLOOR
from velogauss_core.lpips_nets import min_image_size, weights_file

IMAGE_METRICS = ("psnr", "ssim", "lpips_alex", "lpips_vgg")
LPIPS_NETS = {"lpips_alex": "alex", "lpips_vgg": "vgg"}
SPLITS = ("interpolation", "extrapolation")
MOTION_EVAL_TIMES = tuple(np.linspace(0.0, 1.0, 11).tolist())
MOTION_EVAL_POINTS = 2000
MOTION_EVAL_SEED = 0
# The velocity metrics of `velocity_error`, per time and as means (module docstring).
VELOCITY_KEYS = ("relative_l2", "mean_abs", "field_relative_l2", "translation_relative_l2", "spin_relative_l2",
                 "translation_only_relative_l2")


def frame_metrics(pred, gt, lpips_weights=None, with_lpips=True):
    """PSNR, SSIM and (unless `with_lpips` is False) both LPIPS values of one image pair.

    `pred`, `gt`: `H×W×3` arrays or tensors in [0, 1]; `pred` is clipped to [0, 1] first,
    as an 8-bit image of it would be. `lpips_weights`: folder of the LPIPS `.npz` weights
    or None (then `$VELOGAUSS_LPIPS_DIR`, `../shared/data/lpips`, the download). Returns a
    dict of floats keyed by `IMAGE_METRICS` (LPIPS keys absent without LPIPS, and for a
    backbone whose layers do not fit the image: `min_image_size`, 31 px for alex, 16 px for
    vgg, where the official lpips fails too).
    Raises ValueError naming `pred`/`gt` when the shapes differ.
    """
    pred_t, gt_t = _image_tensor("pred", pred), _image_tensor("gt", gt)
    if pred_t.shape != gt_t.shape:
        raise ValueError(f"pred: shape {tuple(pred_t.shape)} differs from gt's {tuple(gt_t.shape)}")
    pred_t = pred_t.clamp(0.0, 1.0)
    with torch.no_grad():
        row = {"psnr": float(metrics.psnr(pred_t, gt_t)), "ssim": float(metrics.ssim(pred_t, gt_t))}
        if with_lpips:
            for key, net in LPIPS_NETS.items():
                if min(pred_t.shape[:2]) >= min_image_size(net):
                    row[key] = float(metrics.lpips(pred_t, gt_t, net=net, weights_dir=lpips_weights))
    return row


def mean_metrics(rows):
    """Mean of each metric over the per-frame dicts `rows`; None for a metric no row has
    (and for an empty split)."""
    means = {}
    for key in IMAGE_METRICS:
        values = [r[key] for r in rows if key in r]
        means[key] = float(np.mean(values)) if values else None
    return means


def render_frames(model, frames, background, time=None, progress=False, desc="render"):
    """Render `model` from each frame's camera; return a list of `H×W×3` float32 arrays.

    `time`: None renders each frame at its own time; a number renders every frame at that
    time (the freeze baseline). `background (3,)`: colour behind the Gaussians.
    """
    images = []
    bg = torch.as_tensor(np.asarray(background, dtype=np.float32))
    with torch.no_grad():
        for frame in tqdm(frames, desc=desc, disable=not progress, leave=False):
            image, _, _ = model.render(frame.camera, frame.time if time is None else time, bg)
            images.append(to_numpy(image).astype(np.float32))
    return images


def lpips_status(lpips_weights=None):
    """`(usable, note)`: whether LPIPS can be computed, and a note for the results.

    An explicit `lpips_weights` folder must hold the weights: `(True, folder)`, and a missing
    file raises later, naming it. With None, the default places and the download are tried
    once; where none works (no ../shared, no network), LPIPS is skipped rather than losing
    a finished run's evaluation: `(False, "skipped: <why>")`, and the LPIPS columns read "—".
    """
    if lpips_weights is not None:
        return True, str(lpips_weights)
    try:
        paths = [weights_file(net) for net in LPIPS_NETS.values()]
    except FileNotFoundError as err:
        return False, f"skipped: {err.strerror}"
    return True, ", ".join(str(p) for p in paths)


def evaluate_split(model, frames, background, lpips_weights=None, progress=False, name="split", with_lpips=None):
    """Render and score one split: `{"frames": [{"path", "time", psnr, ssim, lpips_*}], "mean": {...},
    "count"}`; an empty split gives no frames and None means. `with_lpips`: None decides by
    `lpips_status(lpips_weights)`."""
    if with_lpips is None:
        with_lpips = lpips_status(lpips_weights)[0]
    preds = render_frames(model, frames, background, progress=progress, desc=f"render {name}")
    rows = []
    for frame, pred in tqdm(list(zip(frames, preds)), desc=f"score {name}", disable=not progress, leave=False):
        rows.append({"path": str(frame.path), "time": float(frame.time),
                     **frame_metrics(pred, frame.image, lpips_weights, with_lpips)})
    return {"count": len(rows), "mean": mean_metrics(rows), "frames": rows}


def freeze_baseline(model, frames, background, max_time, progress=False):
    """PSNR and SSIM of the future frames against the model held still at `t = max_time`.

    Returns `{"time": max_time, "count", "mean": {"psnr", "ssim"}, "frames": [...]}`.
    """
    preds = render_frames(model, frames, background, time=max_time, progress=progress, desc="render frozen")
    rows = [{"path": str(f.path), "time": float(f.time), **frame_metrics(p, f.image, with_lpips=False)}
            for f, p in zip(frames, preds)]
    return {"time": float(max_time), "count": len(rows), "mean": mean_metrics(rows), "frames": rows}


def background_baseline(frames, background):
    """PSNR and SSIM of `frames` against an empty render: every pixel the background colour (3,).

    What a model that shows nothing would score: on masked captures, where the subject covers a
    few per cent of the image, an empty frame alone scores well, and a split's PSNR means
    something only above it. Returns `{"count", "mean": {"psnr", "ssim"}, "frames": [...]}`.
    """
    rows = []
    for f in frames:
        empty = np.broadcast_to(np.asarray(background, dtype=np.float32), f.image.shape)
        rows.append({"path": str(f.path), "time": float(f.time), **frame_metrics(empty, f.image, with_lpips=False)})
    return {"count": len(rows), "mean": mean_metrics(rows), "frames": rows}


def moving_surface_points(scene, n_points=MOTION_EVAL_POINTS, seed=MOTION_EVAL_SEED):
    """Points `(M, 3)` on the surfaces of the moving bodies of `scene` (an `AnalyticScene`) at t = 0.

    `n_points` are drawn over all bodies with a fixed seed, then those on static bodies are
    dropped (M ≤ n_points). A surface point belongs to the body it was drawn from, which is
    its nearest body (the catalog's bodies do not touch), hence `margin = inf`.
    """
    points, _, _ = scene.sample_surface(n_points, np.random.default_rng(seed))
    owner = scene.body_index(points, 0.0, margin=np.inf)
    return points[_moving(scene, owner)]


def velocity_error(model, scene, max_time, times=MOTION_EVAL_TIMES, points=None):
    """Error of `model.velocity_at` against the ground-truth velocity on the moving surfaces.

    See the module docstring for the definition. `points`: canonical surface points
    `(M, 3)` (default `moving_surface_points(scene)`). Returns `{"per_time": [{"time", *VELOCITY_KEYS}],
    "observed"/"future"/"all": {*VELOCITY_KEYS}, "points": M}`.
    """
    x0 = moving_surface_points(scene) if points is None else np.asarray(points, dtype=np.float64)
    owner = scene.body_index(x0, 0.0, margin=np.inf)
    rows = []
    gt_norms = [np.linalg.norm(scene.velocity(scene.position(x0, t, margin=np.inf), t, margin=np.inf)) for t in times]
    floor = EVAL_VELOCITY_FLOOR * max(gt_norms, default=0.0)
    for t, gt_norm in zip(times, gt_norms):
        if not model.has_velocity:
            rows.append({"time": float(t), **dict.fromkeys(VELOCITY_KEYS)})
            continue
        x = scene.position(x0, t, margin=np.inf)
        v_gt = scene.velocity(x, t, margin=np.inf)
        v = query(model.particle_velocity, t, x, start=x0)
        v_field = query(model.velocity_at, t, x)
        gt_norm = gt_norm if gt_norm > floor else 0.0
        error = v - v_gt
        translation = body_means(error, owner)
        rows.append({
            "time": float(t),
            "relative_l2": float(np.linalg.norm(error) / gt_norm) if gt_norm > 0 else None,
            "mean_abs": float(np.mean(np.linalg.norm(error, axis=1))) if len(x0) else None,
            "field_relative_l2": float(np.linalg.norm(v_field - v_gt) / gt_norm) if gt_norm > 0 else None,
            "translation_relative_l2": float(np.linalg.norm(translation) / gt_norm) if gt_norm > 0 else None,
            "spin_relative_l2": float(np.linalg.norm(error - translation) / gt_norm) if gt_norm > 0 else None,
            "translation_only_relative_l2":
                float(np.linalg.norm(v_gt - body_means(v_gt, owner)) / gt_norm) if gt_norm > 0 else None,
        })
    return {"points": int(len(x0)), "per_time": rows, **_time_means(rows, max_time, VELOCITY_KEYS)}


class TrueMotion:
    """A stand-in model that moves every point with `scene`'s true velocity (an `AnalyticScene`):
    its velocity errors are zero, and `velocity_error` of it reports the scene's own scores,
    `translation_only_relative_l2`."""

    has_velocity = True

    def __init__(self, scene):
        self.scene = scene

    def velocity_at(self, x, t):
        return torch.as_tensor(self.scene.velocity(to_numpy(x).astype(np.float64), t, margin=np.inf))

    def particle_velocity(self, x0, x, t):
        return self.velocity_at(x, t)


def body_means(values, owner):
    """(M, 3): each row of `values` (M, 3) replaced by the mean of its body's rows (`owner` (M,) ints).

    `values − body_means(values, owner)` is orthogonal to `body_means(values, owner)` (Frobenius),
    so a velocity error splits exactly into its bodies' mean motions and the rest."""
    out = np.zeros_like(values)
    for body in np.unique(owner):
        rows = owner == body
        out[rows] = values[rows].mean(axis=0)
    return out


def trajectory_error(model, scene, max_time, times=MOTION_EVAL_TIMES):
    """Distance between the Gaussians' physics trajectories and the true material paths.

    See the module docstring for the selection of Gaussians and the definition. Returns
    `{"gaussians": M, "per_time": [{"time", "mean_distance", "static_mean_distance"}],
    "observed"/"future"/"all": {...}}`; with no Gaussian selected the distances are None.
    """
    mu0 = query(model.tracked_positions, 0.0)
    opacity = query(lambda t: model.render_inputs_at(t)["opacities"], 0.0).reshape(-1)
    owner = scene.body_index(mu0, 0.0, margin=EVAL_SURFACE_MARGIN)
    keep = (owner >= 0) & (opacity >= ALPHA_MIN)
    keep[keep] = _moving(scene, owner[keep])
    rows = []
    for t in times:
        gt = scene.position(mu0[keep], t, margin=EVAL_SURFACE_MARGIN)
        x = query(model.tracked_positions, t)[keep]
        any_kept = bool(keep.any())
        rows.append({
            "time": float(t),
            "mean_distance": float(np.mean(np.linalg.norm(x - gt, axis=1))) if any_kept else None,
            "static_mean_distance": float(np.mean(np.linalg.norm(mu0[keep] - gt, axis=1))) if any_kept else None,
        })
    means = _time_means(rows, max_time, ("mean_distance", "static_mean_distance"))
    return {"gaussians": int(keep.sum()), "per_time": rows, **means}


@torch.no_grad()  # inference only: no autograd graph of the motion is kept
def evaluate_model(model, scene, splits=SPLITS, lpips_weights=None, ground_truth=None, progress=False):
    """Every metric of the module docstring for `model` on `scene` (a `SceneData`).

    `splits`: a subset of `SPLITS`; the freeze baseline comes with "extrapolation".
    `ground_truth`: the synthetic scene's `AnalyticScene` for the motion metrics, or None.
    Returns a JSON-ready dict: `max_time`, `split` (the scene's data.split), `lpips` (where the
    weights came from, or why LPIPS was skipped: `lpips_status`), `splits` (per split, see
    `evaluate_split`; an empty one, as interpolation may be under "future:F", has count 0 and
    None means: absent, not an error),
    `freeze_baseline` (or None), `background_baseline` (per split, `background_baseline`: an empty
    render's scores), `motion` (`velocity`, `trajectory`, or None).
    Raises ValueError naming `splits` for an unknown split.
    """
    unknown = [s for s in splits if s not in SPLITS]
    if unknown or not splits:
        raise ValueError(f"splits: expected a non-empty subset of {SPLITS}, got {list(splits)}")
    with_lpips, note = lpips_status(lpips_weights)
    if not with_lpips:
        tqdm.write(f"LPIPS {note}")
    result = {"max_time": float(scene.max_time), "split": scene.split, "lpips": note, "splits": {},
              "freeze_baseline": None, "background_baseline": {}, "motion": None}
    for name in splits:
        frames = getattr(scene, name)
        result["splits"][name] = evaluate_split(model, frames, scene.background, lpips_weights, progress, name,
                                                with_lpips)
        result["background_baseline"][name] = background_baseline(frames, scene.background)
    if "extrapolation" in splits:
        result["freeze_baseline"] = freeze_baseline(model, scene.extrapolation, scene.background, scene.max_time,
                                                    progress)
    if ground_truth is not None:
        result["motion"] = {"velocity": velocity_error(model, ground_truth, scene.max_time),
                            "trajectory": trajectory_error(model, ground_truth, scene.max_time)}
    return result


def summary_markdown(result):
    """The headline tables of `result` (from `evaluate_model`) as Markdown: mean image
    metrics per split with the freeze baseline, then the motion errors when present."""
    t = result["max_time"]
    lines = ["| split | frames | PSNR ↑ | SSIM ↑ | LPIPS (alex) ↓ | LPIPS (vgg) ↓ |",
             "|---|---:|---:|---:|---:|---:|"]
    split_rule = result.get("split", "time")
    # Under "future:F" the cut is by count, so a future frame may share the window's end time.
    future = {"time": f"extrapolation (t > {t:g})", "all": "extrapolation (none: data.split \"all\" observes the whole clip)"
              }.get(split_rule, f"extrapolation ({split_rule}, t ≥ {t:g})")
    labels = {"interpolation": f"interpolation (t ≤ {t:g})", "extrapolation": future}
    for name, split in result["splits"].items():
        label = labels[name] if split["count"] else f"{labels[name]}: no frames in this split"
        lines.append(_metric_row(label, split["count"], split["mean"]))
    if result["freeze_baseline"] is not None and result["freeze_baseline"]["count"]:
        base = result["freeze_baseline"]
        lines.append(_metric_row(f"extrapolation, baseline: last observed frame frozen (t = {t:g})",
                                 base["count"], base["mean"]))
    for name, base in (result.get("background_baseline") or {}).items():
        if base["count"]:
            lines.append(_metric_row(f"{name}, baseline: an empty render (the background alone)", base["count"],
                                     base["mean"]))
    motion = result["motion"]
    if motion is not None:
        vel, traj = motion["velocity"], motion["trajectory"]
        lines += ["", f"| motion vs ground truth | observed (t ≤ {t:g}) | future (t > {t:g}) | all |",
                  "|---|---:|---:|---:|"]
        rows = [
            (f"particle velocity relative L2 error ({vel['points']} surface points)", vel, "relative_l2", 3),
            ("  of it, each body's mean motion (translation)", vel, "translation_relative_l2", 3),
            ("  of it, the rest (spin, change of shape)", vel, "spin_relative_l2", 3),
            ("a model with only each body's true mean motion would score", vel, "translation_only_relative_l2", 3),
            ("particle velocity mean error (units / unit time)", vel, "mean_abs", 4),
            ("Eulerian field relative L2 error", vel, "field_relative_l2", 3),
            (f"trajectory mean distance ({traj['gaussians']} Gaussians, units)", traj, "mean_distance", 4),
            ("trajectory mean distance if nothing moved (units)", traj, "static_mean_distance", 4),
        ]
        for label, block, key, digits in rows:
            cells = [_fmt(block[g][key], digits) for g in ("observed", "future", "all")]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def metrics_markdown(result, title="Metrics"):
    """The whole `metrics.md`: headline tables (`summary_markdown`), how the numbers are
    defined, and a per-frame table of each split."""
    parts = [f"# {title}", ""]
    for key in ("run", "trained_by", "data", "split", "lpips"):
        if result.get(key):
            parts.append(f"- {key.replace('_', ' ')}: `{result[key]}`")
    parts += ["", summary_markdown(result), "## Definitions", "", _DEFINITIONS.strip(), ""]
    for name, split in result["splits"].items():
        parts += [f"## Per frame: {name}", "", "| frame | t | PSNR | SSIM | LPIPS (alex) | LPIPS (vgg) |",
                  "|---|---:|---:|---:|---:|---:|"]
        for row in split["frames"]:
            parts.append(f"| {row['path']} | {row['time']:.3f} | " + " | ".join(
                _fmt(row.get(k), d) for k, d in zip(IMAGE_METRICS, (2, 4, 4, 4))) + " |")
        if not split["frames"]:
            parts.append("| (no frames in this split) | | | | | |")
        parts.append("")
    return "\n".join(parts)


_DEFINITIONS = f"""
PSNR (dB, capped at 100), SSIM (11×11 Gaussian window, σ = 1.5) and LPIPS v0.1 as in
spec/losses_metrics.md, each the mean over the split's frames; predictions are clipped to
[0, 1]. The baseline row renders every future frame's camera at the last observed time and
holds it still: the difference to the extrapolation row is what the learned motion buys. The
empty-render rows score the background colour alone against each split: a model that shows
nothing scores that, so a split's PSNR says something only above it.
Velocity: points sampled on the moving bodies' surfaces at t = 0 and carried along their
true paths; at {len(MOTION_EVAL_TIMES)} evenly spaced times in [0, 1], ‖v_learned − v_true‖ / ‖v_true‖ over all points
(a zero prediction scores 1), and the mean per-point error |v_learned − v_true|. The particle
velocity keeps each point's physics code from t = 0 (what moves the Gaussians); the Eulerian
field takes the code at the current point (what the physics losses constrain). The particle
velocity's error splits exactly (the squares add up) into each body's mean motion (its
translation) and the rest (its spin and change of shape); the translation-only row is the
scene's own: what moving every body with its true mean velocity and nothing else would score.
Velocity errors are "—" for a model without a velocity field (deform-only).
Trajectory: Gaussians (opacity ≥ {ALPHA_MIN:.4g}) inside or within {EVAL_SURFACE_MARGIN:g} units of a moving body at
t = 0; mean distance between their physics base positions at t (rendered positions for a
model without a velocity field) and the true positions of the material points they started
on. See velogauss/evaluate.py for the exact definitions.
"""


def _metric_row(label, count, mean):
    cells = [_fmt(mean.get(k), d) for k, d in zip(IMAGE_METRICS, (2, 4, 4, 4))]
    return f"| {label} | {count} | " + " | ".join(cells) + " |"


def _fmt(value, digits):
    return "—" if value is None else f"{value:.{digits}f}"


def _moving(scene, owner):
    moving = np.array([not isinstance(body.motion, StaticMotion) for body in scene.bodies] + [False])
    return moving[owner]  # owner −1 (no body) indexes the trailing False


def _time_means(rows, max_time, keys):
    groups = {"observed": [r for r in rows if r["time"] <= max_time],
              "future": [r for r in rows if r["time"] > max_time], "all": rows}
    out = {}
    for group, members in groups.items():
        out[group] = {}
        for key in keys:
            values = [r[key] for r in members if r[key] is not None]
            out[group][key] = float(np.mean(values)) if values else None
    return out


def query(fn, t, points=None, start=None):
    """`fn(points, t)`, `fn(start, points, t)` when `start` is given, or `fn(t)` when `points`
    is None, as a float64 NumPy array, without gradients; `points (M, 3)` and `start (M, 3)`
    are passed in the dtype and on the device of the model that owns the bound method `fn`
    (float32 on the CPU otherwise)."""
    with torch.no_grad():
        if points is None:
            return to_numpy(fn(float(t))).astype(np.float64)
        owner = getattr(fn, "__self__", None)
        param = next(owner.parameters(), None) if isinstance(owner, torch.nn.Module) else None
        dtype, device = (torch.float32, "cpu") if param is None else (param.dtype, param.device)
        x = torch.as_tensor(np.asarray(points), dtype=dtype, device=device)
        if start is None:
            return to_numpy(fn(x, float(t))).astype(np.float64)
        x0 = torch.as_tensor(np.asarray(start), dtype=dtype, device=device)
        return to_numpy(fn(x0, x, float(t))).astype(np.float64)


def _image_tensor(name, image):
    tensor = torch.as_tensor(to_numpy(image), dtype=torch.float32)
    if tensor.ndim != 3 or tensor.shape[2] != 3:
        raise ValueError(f"{name}: expected an H×W×3 image, got shape {tuple(tensor.shape)}")
    return tensor
