"""Pictures of a trained run: ground truth beside prediction over time, the learned velocity
field, and the Gaussians' trajectories.

Everything is drawn off-screen (matplotlib's Agg backend, Pillow for the label strips) and
written atomically (`velogauss.io_utils`). What `render_run` writes into its output folder:

- `frames/NNN_t<time>_<observed|future>.png`: one camera's view over time, side by side:
  ground truth, the prediction and the absolute error `|gt - pred|` (mean over the colour
  channels, `ERROR_COLORMAP` on [0, `ERROR_DISPLAY_MAX`]), with a label strip on top that
  says "observed window" or "future (extrapolated)" and a time bar below it whose tick
  marks `max_time`, where the future begins;
- `sequence.mp4` (H.264 through the ffmpeg that `imageio-ffmpeg` ships) and `sequence.gif`:
  those frames;
- `filmstrip.png`: up to `FILMSTRIP_COLUMNS` of those times in a grid, ground truth above
  prediction, a vertical red line between the last observed and the first future column;
- `velocity_field.png`: the learned field `velocity_at` on a grid over the slice through
  the centre of the scene box, perpendicular to the box's thinnest axis, at t = 0 and
  t = 1 (in-plane components as arrows, coloured by speed); on synthetic scenes the true
  field is drawn in orange where the slice cuts a body;
- `trajectories.png`: `tracked_positions(t)` (physics positions, or the rendered means of
  a model without a velocity field) of up to `TRAJECTORY_GAUSSIANS` of the most
  opaque Gaussians for t in [0, 1], projected orthographically on the same plane, solid
  while observed, dashed in the future; on synthetic scenes the true paths of the same
  material points in grey. A model without a velocity field gets no `velocity_field.png`.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (the backend must be chosen first)
import numpy as np  # noqa: E402
import torch  # noqa: E402
from PIL import Image, ImageDraw, ImageFont  # noqa: E402
from tqdm.auto import tqdm  # noqa: E402

from velogauss.evaluate import query, render_frames  # noqa: E402
from velogauss.io_utils import save_figure, to_uint8, write_animation, write_png  # noqa: E402
from velogauss_core.constants import EVAL_SURFACE_MARGIN  # noqa: E402

FILMSTRIP_COLUMNS = 8
TRAJECTORY_GAUSSIANS = 150
TRAJECTORY_TIMES = 41
FIELD_GRID = 21
# Small renders (the default synthetic scenes are 128 px) are enlarged by an integer factor,
# nearest neighbour, so that every panel is at least this many pixels high on screen.
MIN_PANEL_HEIGHT = 192
# The error panel's colour scale: a display choice, not a threshold. A mean absolute error of
# 0.25 (a quarter of the full intensity range) is already a wrong object, so saturating there
# keeps small errors visible instead of spending the colour range on rare outliers.
ERROR_DISPLAY_MAX = 0.25
ERROR_COLORMAP = "inferno"
_AXES = "xyz"
_OBSERVED, _FUTURE = (0.15, 0.55, 0.25), (0.85, 0.2, 0.15)


def sequence_frames(interpolation, extrapolation):
    """The frames of one camera over time, sorted by time, for the comparison pictures.

    Frames are grouped by camera pose; the pose seen in the most frames, preferring one
    seen both before and after `max_time`, is chosen. When no pose repeats (monocular
    video, one camera per frame) every evaluation frame is used, in time order.
    Returns a list of `(frame, is_future)`.
    """
    tagged = [(f, False) for f in interpolation] + [(f, True) for f in extrapolation]
    groups = {}
    for frame, future in tagged:
        groups.setdefault(np.round(frame.camera.viewmat, 6).tobytes(), []).append((frame, future))
    best = max(groups.values(), key=lambda g: (len({fut for _, fut in g}), len(g)))
    chosen = best if len(best) > 1 else tagged
    return sorted(chosen, key=lambda item: item[0].time)


def error_image(gt, pred):
    """The absolute error panel, `H×W×3` in [0, 1]: `mean_c |gt - pred|` of `gt`, `pred`
    (`H×W×3` in [0, 1]) through `ERROR_COLORMAP` on [0, `ERROR_DISPLAY_MAX`] (clipped above)."""
    error = np.abs(np.asarray(gt, dtype=np.float64) - np.asarray(pred, dtype=np.float64)).mean(axis=-1)
    return matplotlib.colormaps[ERROR_COLORMAP](np.clip(error / ERROR_DISPLAY_MAX, 0.0, 1.0))[..., :3]


def comparison_image(gt, pred, time, future, max_time, label=True):
    """Ground truth, prediction and absolute error side by side, as one uint8 image `(H', W', 3)`.

    `gt`, `pred`: `H×W×3` in [0, 1]; the third panel is `error_image(gt, pred)`. Panels are
    enlarged by an integer factor (nearest neighbour) to at least `MIN_PANEL_HEIGHT` pixels.
    With `label`, a strip on top names the panels, the time and whether it is observed or
    the future, and a bar below shows `time` on [0, 1] with a tick at `max_time`, filled
    green while observed and red in the future.
    """
    panels = np.concatenate([to_uint8(gt), to_uint8(pred), to_uint8(error_image(gt, pred))], axis=1)
    scale = max(1, -(-MIN_PANEL_HEIGHT // panels.shape[0]))
    panels = np.repeat(np.repeat(panels, scale, axis=0), scale, axis=1)
    if not label:
        return panels
    h, w = panels.shape[:2]
    panel = w // 3
    font = ImageFont.load_default()
    strip, bar = 28, 10
    canvas = Image.new("RGB", (w, h + strip + bar), (255, 255, 255))
    canvas.paste(Image.fromarray(panels), (0, strip))
    draw = ImageDraw.Draw(canvas)
    status = "future (extrapolated)" if future else "observed window"
    draw.text((3, 2), "ground truth", fill=(0, 0, 0), font=font)
    draw.text((panel + 3, 2), f"prediction  t={time:.3f}", fill=(0, 0, 0), font=font)
    draw.text((panel + 3, 14), status, fill=tuple(int(255 * c) for c in (_FUTURE if future else _OBSERVED)), font=font)
    draw.text((2 * panel + 3, 2), f"|error| (0 to {ERROR_DISPLAY_MAX:g})", fill=(0, 0, 0), font=font)
    for x in (panel, 2 * panel):
        draw.line([(x, 0), (x, strip)], fill=(128, 128, 128))
    y0 = h + strip + 2
    draw.rectangle([0, y0, w - 1, y0 + bar - 4], outline=(160, 160, 160))
    fill = _OBSERVED if not future else _FUTURE
    draw.rectangle([0, y0, int(round(time * (w - 1))), y0 + bar - 4], fill=tuple(int(255 * c) for c in fill))
    x_split = int(round(max_time * (w - 1)))
    draw.line([(x_split, y0 - 2), (x_split, y0 + bar - 2)], fill=(0, 0, 0), width=2)
    return np.asarray(canvas)


def filmstrip_figure(items, gts, preds, max_time):
    """A figure: ground truth (top row) and prediction (bottom row) at up to
    `FILMSTRIP_COLUMNS` evenly chosen times, a red line where the future begins."""
    idx = np.unique(np.round(np.linspace(0, len(items) - 1, min(FILMSTRIP_COLUMNS, len(items)))).astype(int))
    fig, axes = plt.subplots(2, len(idx), figsize=(1.6 * len(idx), 3.6), squeeze=False)
    for col, i in enumerate(idx):
        frame, future = items[i]
        for row, image in enumerate((gts[i], preds[i])):
            ax = axes[row, col]
            ax.imshow(np.clip(image, 0.0, 1.0))
            ax.set_xticks([])
            ax.set_yticks([])
        axes[0, col].set_title(f"t={frame.time:.2f}" + (" (future)" if future else ""), fontsize=8,
                               color=_FUTURE if future else "black")
    axes[0, 0].set_ylabel("ground truth")
    axes[1, 0].set_ylabel("prediction")
    fig.tight_layout()
    futures = [col for col, i in enumerate(idx) if items[i][1]]
    if futures and futures[0] > 0:
        left = axes[0, futures[0] - 1].get_position().x1
        right = axes[0, futures[0]].get_position().x0
        fig.add_artist(plt.Line2D([(left + right) / 2] * 2, [0.02, 0.98], color="red", linewidth=2,
                                  transform=fig.transFigure))
    fig.suptitle(f"observed t ≤ {max_time:g} | future t > {max_time:g}", fontsize=9, y=1.02)
    return fig


def slice_plane(bounds):
    """`(normal_axis, (a, b))`: the axis along which the box `bounds (2, 3)` is thinnest (the
    first on ties) and the two in-plane axes in increasing order. Motion mostly happens
    along the box's long axes, so the slice across its thinnest one shows most of it."""
    extent = np.asarray(bounds[1]) - np.asarray(bounds[0])
    normal = int(np.argmin(extent))
    return normal, tuple(a for a in range(3) if a != normal)


def velocity_field_figure(model, bounds, times=(0.0, 1.0), ground_truth=None):
    """A figure with one panel per time: `velocity_at` on a `FIELD_GRID²` grid over the
    slice through the centre of `bounds (2, 3)` (see `slice_plane`), plus the Gaussians
    within 10% of the box's thickness of the slice as faint dots, and `ground_truth`'s
    field (an `AnalyticScene`, or None) in orange at the grid points inside a body."""
    bounds = np.asarray(bounds, dtype=np.float64)
    normal, (a, b) = slice_plane(bounds)
    centre = bounds.mean(axis=0)
    pad = 0.05 * (bounds[1] - bounds[0]).max()
    ga = np.linspace(bounds[0, a] - pad, bounds[1, a] + pad, FIELD_GRID)
    gb = np.linspace(bounds[0, b] - pad, bounds[1, b] + pad, FIELD_GRID)
    A, B = np.meshgrid(ga, gb)
    points = np.tile(centre, (A.size, 1))
    points[:, a], points[:, b] = A.ravel(), B.ravel()
    thickness = 0.1 * max(bounds[1, normal] - bounds[0, normal], pad)
    fig, axes = plt.subplots(1, len(times), figsize=(5.0 * len(times), 4.6), squeeze=False)
    for ax, t in zip(axes[0], times):
        v = query(model.velocity_at, t, points)
        speed = np.linalg.norm(v, axis=1)
        means = query(model.tracked_positions, t)
        near = np.abs(means[:, normal] - centre[normal]) < thickness
        ax.scatter(means[near, a], means[near, b], s=2, color="0.75", label="Gaussians near the slice")
        q = ax.quiver(points[:, a], points[:, b], v[:, a], v[:, b], speed, cmap="viridis", angles="xy",
                      scale=_quiver_scale(v))
        fig.colorbar(q, ax=ax, label="learned speed |v|")
        if ground_truth is not None:
            inside = ground_truth.body_index(points, t) >= 0
            if np.any(inside):
                v_gt = ground_truth.velocity(points[inside], t)
                ax.quiver(points[inside, a], points[inside, b], v_gt[:, a], v_gt[:, b], color="tab:orange",
                          angles="xy", width=0.003, scale=_quiver_scale(v_gt), label="ground truth (inside bodies)")
        ax.set_title(f"learned velocity field, t = {t:g}, slice {_AXES[normal]} = {centre[normal]:.2f}")
        ax.set_xlabel(_AXES[a])
        ax.set_ylabel(_AXES[b])
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    return fig


def _quiver_scale(v):
    """matplotlib's autoscale (None), except for an all-zero field, where autoscaling divides
    by its zero mean length: any fixed scale draws the zero-length arrows (as dots)."""
    return None if np.any(v) else 1.0


def trajectories_figure(model, bounds, max_time, ground_truth=None):
    """A figure of `tracked_positions(t)`, t in [0, 1], of the `TRAJECTORY_GAUSSIANS` most opaque
    Gaussians, projected on the plane of `slice_plane(bounds)`: solid for `t ≤ max_time`,
    dashed after; `ground_truth` (an `AnalyticScene`, or None) adds the true paths in grey."""
    _, (a, b) = slice_plane(bounds)
    opacity = query(lambda t: model.render_inputs_at(t)["opacities"], 0.0).reshape(-1)
    chosen = np.sort(np.argsort(-opacity, kind="stable")[:TRAJECTORY_GAUSSIANS])
    times = np.unique(np.concatenate([np.linspace(0.0, 1.0, TRAJECTORY_TIMES), [max_time]]))
    paths = np.stack([query(model.tracked_positions, t)[chosen] for t in times])  # (T, M, 3)
    observed = times <= max_time
    fig, ax = plt.subplots(figsize=(6.0, 5.2))
    if ground_truth is not None:
        gt = np.stack([ground_truth.position(paths[0], t, margin=EVAL_SURFACE_MARGIN) for t in times])
        ax.plot(gt[:, :, a], gt[:, :, b], color="0.6", linewidth=0.6)
        ax.plot([], [], color="0.6", label="ground truth path")
    ax.plot(paths[observed][:, :, a], paths[observed][:, :, b], color=_OBSERVED, linewidth=0.8)
    future = times >= max_time
    ax.plot(paths[future][:, :, a], paths[future][:, :, b], color=_FUTURE, linewidth=0.8, linestyle="--")
    ax.scatter(paths[0, :, a], paths[0, :, b], s=4, color="black", zorder=3, label="t = 0")
    ax.plot([], [], color=_OBSERVED, label=f"learned, observed (t ≤ {max_time:g})")
    ax.plot([], [], color=_FUTURE, linestyle="--", label=f"learned, future (t > {max_time:g})")
    ax.set_xlabel(_AXES[a])
    ax.set_ylabel(_AXES[b])
    ax.set_aspect("equal")
    ax.set_title(f"trajectories of {len(chosen)} Gaussians (physics base state)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


@torch.no_grad()  # inference only: no autograd graph of the motion is kept
def render_run(model, scene, out_dir, fps=8, ground_truth=None, label=True, progress=False):
    """Write every picture listed in the module docstring into `out_dir`; return their paths.

    `model`: a trained `VeloGaussModel`; `scene`: its `SceneData`; `fps` > 0 for the
    animation; `ground_truth`: the synthetic scene's `AnalyticScene`, or None.
    Raises ValueError naming `fps` when it is not positive.
    """
    if not fps > 0:
        raise ValueError(f"fps: expected a positive number, got {fps!r}")
    out = Path(out_dir)
    items = sequence_frames(scene.interpolation, scene.extrapolation)
    preds = render_frames(model, [f for f, _ in items], scene.background, progress=progress, desc="render frames")
    gts = [f.image for f, _ in items]
    written = []
    pictures = []
    for k, ((frame, future), gt, pred) in enumerate(tqdm(list(zip(items, gts, preds)), desc="write frames",
                                                          disable=not progress, leave=False)):
        picture = comparison_image(gt, pred, frame.time, future, scene.max_time, label=label)
        path = out / "frames" / f"{k:03d}_t{frame.time:.3f}_{'future' if future else 'observed'}.png"
        write_png(path, picture.astype(np.float32) / 255.0)
        pictures.append(picture.astype(np.float32) / 255.0)
        written.append(path)
    for name in ("sequence.mp4", "sequence.gif"):
        write_animation(out / name, pictures, fps)
        written.append(out / name)
    figures = [("filmstrip.png", lambda: filmstrip_figure(items, gts, preds, scene.max_time)),
               ("trajectories.png", lambda: trajectories_figure(model, scene.bounds, scene.max_time, ground_truth))]
    if model.has_velocity:
        figures.append(("velocity_field.png",
                        lambda: velocity_field_figure(model, scene.bounds, ground_truth=ground_truth)))
    for name, make in figures:
        fig = make()
        try:
            save_figure(out / name, fig)
        finally:
            plt.close(fig)
        written.append(out / name)
    return written
