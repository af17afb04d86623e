"""Motion fidelity study: where the velocity error enters, and which training scheme removes it.

Three levels per catalogue scene (velogauss.scenes.catalog), each scored with the motion
metrics of `velogauss.evaluate` (particle velocity relative L2 error over the observed and the
future times; physics trajectory error against the nothing-moved error) and, from images,
the interpolation / extrapolation PSNR and the freeze baseline:

* `fit` -- the representational floor: the motion model alone (`no-adf` ablation, no
  rendering) fitted to the analytic trajectories of points on the moving bodies' surfaces at
  the observed frame times (t <= max_time), by Adam on the mean squared position error. The
  positions at successive frame times come from one chained integration (VG-STEP). The
  variant's and `--set` overrides apply (e.g. `model.patterns=mlp`: the time network), and each parameter group
  is trained at its training rate relative to the networks'.
  `fit-all` fits every frame time in [0, 1] (what the basis can express at all).
* `opt` -- the optimisation floor: training from images with the Gaussians initialised on
  the true bodies at t = 0 with their true colours (the generated `points3d.ply`), no
  densification or opacity reset, and only the motion training after the warm-up
  (`train.motion_only`).
* `full` -- the full pipeline (`velogauss train` defaults plus the variant's overrides).

Every run's numbers are cached as JSON under `--cache` (default runs/fidelity), so the
tables can be rebuilt (`table`) without retraining. Results go to benchmarks/FIDELITY.md.

Regenerate (one core: export OMP_NUM_THREADS=1):
  velogauss bench fidelity run --scenes toss,stretch --seeds 0 --levels fit,fit-all,opt,full --variants a
  velogauss bench fidelity run --scenes toss --seeds 0,1 --levels full --variants a,b
  velogauss bench fidelity table --scenes all --levels all --variants all --seeds all
  velogauss bench fidelity run --scenes toss --seeds 0,1 --levels full --variants cost-v1-i2000,...
  velogauss bench fidelity pareto   (accuracy against training time, from the cost-* runs)
  velogauss bench fidelity run --scenes grow@128 --levels full   (a scene at 128 x 128 px)
(`rescore` recomputes the motion scores of the selected trained runs from their checkpoints.)
"""

import json
import time
from pathlib import Path

import numpy as np
import torch

from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.evaluate import (MOTION_EVAL_TIMES, evaluate_split, freeze_baseline, moving_surface_points,
                                trajectory_error, velocity_error)
from velogauss.io_utils import write_text
from velogauss.model import build_model
from velogauss.model.build import scene_spec
from velogauss.scenes import make_scene
from velogauss.scenes.catalog import SCENES
from velogauss.train.optim import make_optimizer
from velogauss_fast.motion.code import physics_code
from velogauss_fast.physics.acceleration import acceleration_field
from velogauss_fast.motion.trajectory import base_state

LEVELS = ("fit", "fit-all", "opt", "full")
# The variants that can be run: config overrides on the current defaults. "a": the defaults,
# scheme (a) of spec/motion.md; "b": scheme (b); then the paper's ablations. Records of other
# variants (earlier versions' defaults and probes) stay in the cache as data: each holds the
# overrides it ran with.
VARIANTS = {
    "a": [],
    "b": ["model.scheme=adf-step"],
    "a-no-gpc": ["model.ablation=no-gpc"],
    "a-no-adf": ["model.ablation=no-adf"],
    "a-no-pds": ["model.ablation=no-pds"],
    "deform-only": ["model.ablation=deform-only"],
}
# Accuracy against training time (the `pareto` command): each variant changes what one run
# costs -- views per iteration, iterations, motion patterns K, integrator -- and nothing else.
COST_VARIANTS = {
    **{f"cost-v{v}-i{i}": [f"train.views={v}", f"train.iterations={i}"]
       for v in (1, 3) for i in (2000, 3000, 6000)},
    "cost-v3-k8": ["train.views=3", "model.n_patterns=8"],
    "cost-v3-euler": ["train.views=3", "model.integrator=euler"],
    "cost-v3-rk4": ["train.views=3", "model.integrator=rk4"],
}
VARIANTS.update(COST_VARIANTS)
DEFAULT_COST = "cost-v3-i3000"
OPT_FLOOR = ["train.motion_only=true", "densify.until=0", "densify.opacity_reset_every=0"]
# The representational fit: points on the moving surfaces (a seed other than the
# evaluation's), Adam iterations and learning rate (decayed 100x, log-linearly).
FIT_POINTS, FIT_SEED, FIT_ITERATIONS, FIT_LR = 600, 1, 3000, 3e-3
FRAME_TIMES = np.linspace(0.0, 1.0, 21)  # the generated scenes' frame times (make_scene's n_times)


def scene_dir(cache, name):
    """The generated scene `name` under `cache`/data, made once: a catalogue name at the
    catalogue's defaults, or `NAME@PIXELS` for the same scene rendered at PIXELS × PIXELS
    (the resolution lever of the error budget)."""
    path = Path(cache) / "data" / name
    if not (path / "transforms_train.json").is_file():
        base, _, pixels = name.partition("@")
        make_scene(base, path, **({"resolution": int(pixels)} if pixels else {}))
    return path


def motion_scores(model, scene, max_time):
    """Velocity and trajectory errors (velogauss.evaluate) reduced to the study's numbers."""
    vel = velocity_error(model, scene, max_time)
    traj = trajectory_error(model, scene, max_time)
    out = {"gaussians_tracked": traj["gaussians"]}
    for split in ("observed", "future"):
        out[f"vel_{split}"] = vel[split]["relative_l2"]
        out[f"field_{split}"] = vel[split]["field_relative_l2"]
        moved, still = traj[split]["mean_distance"], traj[split]["static_mean_distance"]
        out[f"traj_{split}"] = moved
        out[f"traj_ratio_{split}"] = moved / still if moved is not None and still else None
    out.update(acceleration_scores(model, scene, max_time))
    return out


@torch.no_grad()
def acceleration_scores(model, scene, max_time, times=MOTION_EVAL_TIMES):
    """{"acc_observed", "acc_future"}: relative L2 error of the learned acceleration field
    a(x, t) (VG-ACC, what the transport residual asks Dv/Dt to be) at the true positions of
    the moving surface points, against the scene's material acceleration; means over the
    observed and the future times. None without the affine velocity (nothing to compare)
    or where the true acceleration vanishes."""
    spec = model.spec
    if spec.velocity != "affine":
        return {"acc_observed": None, "acc_future": None}
    x0 = moving_surface_points(scene)
    params = model.motion.params()
    rows = {"observed": [], "future": []}
    for t in times:
        x = scene.position(x0, t, margin=np.inf)
        truth = scene.acceleration(x, t, margin=np.inf)
        norm = np.linalg.norm(truth)
        if norm == 0.0:
            continue
        learned = acceleration_field(params, torch.as_tensor(x, dtype=torch.float32), t, spec).numpy()
        rows["observed" if t <= max_time else "future"].append(float(np.linalg.norm(learned - truth) / norm))
    return {f"acc_{split}": float(np.mean(v)) if v else None for split, v in rows.items()}


def fit_level(name, seed, overrides, all_times, max_time=0.75):
    """The `fit` / `fit-all` level (module docstring): returns the scores and the final loss."""
    scene = SCENES[name.partition("@")[0]]()  # the motion does not depend on the resolution
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    cfg = load_config(None, ["model.ablation=no-adf", *overrides])
    spec = scene_spec(cfg, {"effects": scene.effects, "incompressible": scene.incompressible})
    x0 = moving_surface_points(scene, FIT_POINTS, FIT_SEED)
    model = build_model(cfg, spec, x0, None, rng)
    times = [float(t) for t in FRAME_TIMES if all_times or t <= max_time + 1e-9]
    targets = [torch.as_tensor(scene.position(x0, t, margin=np.inf), dtype=torch.float32) for t in times]
    # The training's motion groups (velogauss.train.optim), each at FIT_LR times its rate
    # relative to the networks': the larger rate of Q and of rigid patterns carries over.
    groups = [g for g in make_optimizer(model, cfg.train, 1.0).param_groups if g["name"] in ("motion", "acc")]
    scale = [FIT_LR * g["lr"] / cfg.train.lr_motion for g in groups]
    optimizer = torch.optim.Adam([{"params": g["params"]} for g in groups], lr=FIT_LR)
    clock = time.perf_counter()
    g = model.gaussians
    for it in range(FIT_ITERATIONS):
        for group, lr in zip(optimizer.param_groups, scale):
            group["lr"] = lr * 0.01 ** (it / FIT_ITERATIONS)
        loss = _chained_loss(model, g.means.detach(), torch.nn.functional.normalize(g.quats.detach(), dim=1),
                             g.scales.detach(), times, targets)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    wall = time.perf_counter() - clock
    model.eval()
    return {**motion_scores(model, scene, max_time), "fit_rmse": float(loss.detach()) ** 0.5, "wall_s": wall}


def _chained_loss(model, x0, q0, s0, times, targets):
    """Mean squared position error at `times`, integrating from each time to the next (VG-STEP)."""
    params, spec = model.motion.params(), model.spec
    z = physics_code(params, x0, spec)
    x, q, s, t_prev, total = x0, q0, s0, 0.0, 0.0
    for t, gt in zip(times, targets):
        if t > t_prev:
            x, q, s = base_state(params, x, q, s, z, t, spec.step, spec.integrator, spec, t0=t_prev)
        total = total + ((x - gt) ** 2).sum(1).mean()
        t_prev = t
    return total / len(times)


def train_level(name, seed, overrides, cache, tag):
    """The `opt` / `full` level: train from the generated images, then score images and motion."""
    from velogauss.train.loop import train

    data_dir = scene_dir(cache, name)
    cfg = load_config(None, [f"train.seed={seed}", "train.eval_every=0", "train.checkpoint_every=0",
                             f"data.dir={data_dir}", *overrides])
    data = load_scene(data_dir, max_time=cfg.data.max_time, half_res=cfg.data.half_res,
                      background=cfg.data.background, split=cfg.data.split)
    clock = time.perf_counter()
    model = train(cfg, data, Path(cache) / "runs" / tag, progress=False)
    wall = time.perf_counter() - clock
    from velogauss.scenes import load_ground_truth

    scene = load_ground_truth(data_dir)
    with torch.no_grad():
        interp = evaluate_split(model, data.interpolation, data.background, with_lpips=False)["mean"]["psnr"]
        extrap = evaluate_split(model, data.extrapolation, data.background, with_lpips=False)["mean"]["psnr"]
        frozen = freeze_baseline(model, data.extrapolation, data.background, data.max_time)["mean"]["psnr"]
    return {**motion_scores(model, scene, data.max_time), "interp_psnr": interp, "extrap_psnr": extrap,
            "frozen_psnr": frozen, "wall_s": wall, "n_gaussians": len(model.gaussians),
            "n_moving": int(model.moving.sum())}


def run_one(name, level, variant, seed, cache, extra=()):
    """Run (or read from the cache) one (scene, level, variant, seed); returns its record."""
    tag = f"{name}-{level}-{variant}-s{seed}"
    file = Path(cache) / "results" / f"{tag}.json"
    overrides = [*VARIANTS[variant], *extra] if variant in VARIANTS else None
    if file.is_file():
        record = json.loads(file.read_text())
        # A record of another version under a name this one runs differently is not its result.
        if overrides is not None and record.get("overrides") != overrides:
            raise ValueError(f"{file}: recorded with the overrides {record.get('overrides')}, and {variant!r} now "
                             f"runs {overrides}; choose another --cache (the record stays as data)")
        return record
    if overrides is None:
        raise ValueError(f"--variants: {variant!r} cannot be run: choose from {', '.join(sorted(VARIANTS))}")
    if level in ("fit", "fit-all"):
        scores = fit_level(name, seed, overrides, all_times=level == "fit-all")
    else:
        scores = train_level(name, seed, overrides + (OPT_FLOOR if level == "opt" else []), cache, tag)
    record = {"scene": name, "level": level, "variant": variant, "seed": seed, "overrides": overrides, **scores}
    write_text(file, json.dumps(record, indent=1))
    return record


def rescore(record, cache):
    """The record with its motion scores recomputed from the run's final checkpoint (after a
    change of the metric, e.g. EVAL_VELOCITY_FLOOR); fit levels keep no checkpoint and are
    returned unchanged."""
    from velogauss.scenes import load_ground_truth
    from velogauss.train.checkpoint import load_model

    if record["level"] not in ("opt", "full"):
        return record
    tag = f"{record['scene']}-{record['level']}-{record['variant']}-s{record['seed']}"
    model, cfg = load_model(Path(cache) / "runs" / tag)
    scene = load_ground_truth(scene_dir(cache, record["scene"]))
    updated = {**record, **motion_scores(model, scene, cfg.data.max_time)}
    write_text(Path(cache) / "results" / f"{tag}.json", json.dumps(updated, indent=1))
    return updated


COLUMNS = [("vel_observed", "vel. err obs", "{:.3f}"), ("vel_future", "vel. err fut", "{:.3f}"),
           ("acc_observed", "acc. err obs", "{:.3f}"), ("acc_future", "acc. err fut", "{:.3f}"),
           ("traj_ratio_observed", "traj/still obs", "{:.3f}"), ("traj_ratio_future", "traj/still fut", "{:.3f}"),
           ("interp_psnr", "interp dB", "{:.2f}"), ("extrap_psnr", "extrap dB", "{:.2f}"),
           ("frozen_psnr", "frozen dB", "{:.2f}"), ("wall_s", "wall s", "{:.0f}")]


def table(records):
    """Markdown table: one row per (scene, level, variant), the mean over its seeds (seed count shown)."""
    groups = {}
    for r in records:
        groups.setdefault((r["scene"], r["level"], r["variant"]), []).append(r)
    head = "| scene | level | variant | seeds | " + " | ".join(c[1] for c in COLUMNS) + " |"
    lines = [head, "|" + "---|" * (4 + len(COLUMNS))]
    for (scene, level, variant), rows in sorted(groups.items(), key=lambda kv: (kv[0][0], LEVELS.index(kv[0][1]),
                                                                                 kv[0][2])):
        cells = []
        for key, _, fmt in COLUMNS:
            values = [r[key] for r in rows if r.get(key) is not None]
            cells.append(fmt.format(float(np.mean(values))) if values else "—")
        lines.append(f"| {scene} | {level} | {variant} | {len(rows)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def pareto_front(costs, scores, sign):
    """The (cost, score) pairs on the Pareto front, by increasing cost: each one scores better
    (higher when sign = +1, lower when -1) than every cheaper one."""
    front = []
    for x, y in sorted(zip(costs, scores)):
        if not front or sign * y > sign * front[-1][1]:
            front.append((x, y))
    return front


def pareto_panel(ax, xs, ys, spread, labels, sign, xlabel, ylabel):
    """Draw one accuracy-against-cost panel on `ax`: the points (xs, ys) with error bars `spread`
    ([below], [above]), each annotated with its label, and the Pareto front joined (`sign`: +1
    where higher is better, -1 where lower is)."""
    ax.errorbar(xs, ys, yerr=spread, fmt="o", capsize=3)
    for x, y, label in zip(xs, ys, labels):
        ax.annotate(label, (x, y), fontsize=7, xytext=(3, 3), textcoords="offset points")
    front = pareto_front(xs, ys, sign)
    if front:
        ax.plot(*zip(*front), "-", alpha=0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)


def pareto_plot(records, path, scene="toss"):
    """Write `path` (PNG): extrapolation PSNR and future velocity error against training wall
    time on `scene`, one point per cost variant (mean over its seeds, bars: min-max), the runs
    on the Pareto front joined. Returns the Markdown table of the plotted points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = {}
    for r in records:
        # The defaults are one of the cost points: 3 views, 3000 iterations (velogauss.config).
        variant = DEFAULT_COST if r["variant"] == "a" else r["variant"]
        if variant in COST_VARIANTS and r["level"] == "full" and r["scene"] == scene:
            groups.setdefault(variant, []).append(r)
    points = []
    for variant, rows in sorted(groups.items()):
        stats = {key: [float(r[key]) for r in rows] for key in ("wall_s", "extrap_psnr", "vel_future")}
        points.append((variant, len(rows), stats))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    # sign: +1 where higher is better.
    for ax, key, label, sign in ((axes[0], "extrap_psnr", "extrapolation PSNR (dB)", 1.0),
                                 (axes[1], "vel_future", "future velocity rel. error", -1.0)):
        xs = [np.mean(p[2]["wall_s"]) for p in points]
        ys = [np.mean(p[2][key]) for p in points]
        spread = [[y - min(p[2][key]) for y, p in zip(ys, points)], [max(p[2][key]) - y for y, p in zip(ys, points)]]
        pareto_panel(ax, xs, ys, spread, [p[0].removeprefix("cost-") for p in points], sign,
                     "training wall time (s, one thread)", label)
    fig.suptitle(f"{scene}, full pipeline: accuracy against training time")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    lines = ["| variant | seeds | wall s | extrap dB | vel. err fut |", "|---|---|---|---|---|"]
    for variant, n, stats in points:
        lines.append(f"| {variant} | {n} | " + " | ".join(
            f"{np.mean(stats[k]):{f}} ({min(stats[k]):{f}}–{max(stats[k]):{f}})"
            for k, f in (("wall_s", ".0f"), ("extrap_psnr", ".2f"), ("vel_future", ".3f"))) + " |")
    return "\n".join(lines)


def load_records(cache):
    return [json.loads(p.read_text()) for p in sorted((Path(cache) / "results").glob("*.json"))]


def study(action, scenes="toss", seeds="0", levels="full", variants="a", overrides=(), cache="runs/fidelity",
          threads=1, plot="benchmarks/fidelity/pareto.png"):
    """`velogauss bench fidelity ACTION`: "run" trains and scores every selected run (scenes,
    seeds, levels, variants: comma-separated) and prints the table; "table" prints it from the
    cache; "rescore" recomputes the motion scores from the checkpoints; "pareto" plots accuracy
    against training time into `plot`. `overrides`: extra config KEY=VALUE for every run."""
    torch.set_num_threads(threads)
    selection = {"scene": scenes, "level": levels, "variant": variants, "seed": seeds}
    if action == "run":
        for name in scenes.split(","):
            for level in levels.split(","):
                for variant in variants.split(","):
                    for seed in (int(s) for s in seeds.split(",")):
                        record = run_one(name, level, variant, seed, cache, list(overrides))
                        print(json.dumps({k: record.get(k) for k in ("scene", "level", "variant", "seed",
                                                                      *(c[0] for c in COLUMNS))}), flush=True)
    records = [r for r in load_records(cache) if action == "run" or _selected(r, selection)]
    if action == "rescore":
        records = [rescore(r, cache) for r in records]
    if action == "pareto":
        print(pareto_plot(load_records(cache), plot, scenes.split(",")[0]))
        return
    print(table(records))


def _selected(record, selection):
    """Whether a cached record is in the `selection` {"scene", "level", "variant", "seed": comma-separated
    values, or "all"}."""
    return all(value == "all" or str(record[key]) in value.split(",") for key, value in selection.items())
