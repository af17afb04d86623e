"""Accuracy against training time on the scene family: the default run of each scene beside
shorter ones, and the Pareto front of the budgets.

`velogauss bench family budgets --seeds S --fractions 0.25,0.5 --out OUT` renders each seed's
scene into `OUT/data/random-SEED/` (as `velogauss bench family scenes` does) and writes
`OUT/grid.toml`: every scene's default run (`OUT/random-SEED-full-s0/`, the family study's own
folder, so a study's runs serve both) and, per fraction f, a run of `round(f · N)` iterations,
N being the number the default resolves for that scene (`train.iterations = "auto"`:
monocular video gets more, velogauss.train.sampling.auto_iterations), in
`OUT/random-SEED-full-s0-train.iterations=<n>/`. The schedule's "auto" keys scale with it.

`velogauss bench family pareto --out OUT --plot P.png` reads every finished run of those names
and, per budget (the fraction of its scene's default iterations), gives over the scenes the
median and the 10th–90th percentile range of
- its cost: the training's wall time (log.jsonl's last `elapsed_s`) plus the form's probe
  (motion_form.json's `probe_s`), over its scene's default run's, and in seconds;
- the particle velocity's relative error observed and future, and extrapolation minus the frozen
  frame (dB), the family's targets (velogauss.bench.family).

The plot draws each metric against the median cost ratio and joins the budgets on the Pareto
front (velogauss.bench.fidelity.pareto_panel). Times are whatever the runs took where they ran:
compare budgets trained side by side in one sweep, one thread each.
"""

import json
import os
import re
from pathlib import Path

import numpy as np
import tomli_w

from velogauss.bench.family import RUN_SEED, make_scenes, parse_seeds
from velogauss.bench.fidelity import pareto_panel
from velogauss.io_utils import atomic_path, write_text

# The budget's key in a run's name (velogauss/sweep/grid.py names a point by its settings).
_BUDGET = re.compile(r"^(?P<scene>random-\d+)-full-s" + str(RUN_SEED) + r"(?:-train\.iterations=(?P<n>\d+))?$")
# Where lower is better (+1 for higher), for the front: what each plotted metric is.
METRICS = (("vel_obs", "velocity error, observed", -1.0), ("vel_fut", "velocity error, future", -1.0),
           ("gain_frozen", "extrapolation − frozen (dB)", 1.0))


def parse_fractions(text):
    """`--fractions`: comma-separated numbers in (0, 1), duplicates dropped; ValueError naming it."""
    try:
        values = [float(s) for s in text.split(",") if s.strip()]
    except ValueError:
        values = []
    if not values or not all(0.0 < v < 1.0 for v in values):
        raise ValueError(f"--fractions: expected comma-separated numbers in (0, 1), got {text!r}")
    return tuple(dict.fromkeys(values))


def default_iterations(folder):
    """The iterations `train.iterations = "auto"` resolves to for the scene in `folder`, as training does."""
    from velogauss.config import load_config
    from velogauss.data import load_scene
    from velogauss.model import scene_spec
    from velogauss.train.sampling import auto_iterations

    cfg = load_config(None, [])
    data = load_scene(folder)
    return auto_iterations([f.time for f in data.train], cfg.train.views, scene_spec(cfg, data.metadata).moving)


def write_budget_grid(out, folders, fractions):
    """Write `out/grid.toml`: each folder's default run and one run per fraction; return its path."""
    out = Path(out).absolute()
    # Not resolved: a scene folder may be a link into another study's data/.
    rel = [str(Path(f).absolute().relative_to(out)) for f in folders]
    grids = [{"data": rel, "ablations": ["full"], "seeds": [RUN_SEED]}]
    for folder, name in zip(folders, rel):
        n = default_iterations(folder)
        budgets = sorted({max(1, round(f * n)) for f in fractions} - {n})
        grids.append({"data": [name], "ablations": ["full"], "seeds": [RUN_SEED],
                      "set": {"train.iterations": budgets}})
    path = out / "grid.toml"
    write_text(path, "# Written by `velogauss bench family budgets`: each scene's default and shorter runs.\n"
                     + tomli_w.dumps({"out": str(out), "threads": 1, "grid": grids}))
    return path


def budgets(seeds, fractions, out, echo=print):
    """`velogauss bench family budgets`: the scenes and their grid; echoes the sweep to run next."""
    fractions = parse_fractions(fractions)
    folders = make_scenes(parse_seeds(seeds), out, echo)
    path = write_budget_grid(out, folders, fractions)
    echo(f"grid: {path}\nnext: velogauss sweep {path} --cpus {os.cpu_count()}")
    return path


def run_record(run):
    """What the study reads of one finished run folder: iterations, cost (s) and the scores."""
    metrics = json.loads((run / "metrics.json").read_text())
    last = json.loads((run / "log.jsonl").read_text().strip().splitlines()[-1])
    form = run / "motion_form.json"
    probe = json.loads(form.read_text()).get("probe_s", 0.0) if form.is_file() else 0.0
    extrap = metrics["splits"].get("extrapolation", {}).get("mean", {}).get("psnr")
    velocity = metrics.get("motion", {}).get("velocity", {})
    return {"iterations": int(last["iteration"]), "cost_s": float(last["elapsed_s"]) + float(probe or 0.0),
            "vel_obs": velocity.get("observed", {}).get("relative_l2"),
            "vel_fut": velocity.get("future", {}).get("relative_l2"),
            "gain_frozen": None if extrap is None else extrap - metrics["freeze_baseline"]["mean"]["psnr"]}


def collect(out):
    """Records of every finished run under `out` named as `budgets` names them, each with its
    scene, `fraction` of and `cost_ratio` to its scene's default run; scenes whose default run has
    not finished are left out."""
    runs = {}
    for path in sorted(Path(out).iterdir()):
        match = _BUDGET.match(path.name)
        if match and (path / "metrics.json").is_file():
            runs.setdefault(match["scene"], {})[match["n"]] = run_record(path)
    records = []
    for scene, by_budget in sorted(runs.items()):
        default = by_budget.get(None)
        if default is None:
            continue
        for record in by_budget.values():
            records.append({"scene": scene, **record, "fraction": record["iterations"] / default["iterations"],
                            "cost_ratio": record["cost_s"] / default["cost_s"]})
    return records


def summary(records):
    """`[(fraction, n scenes, {key: (median, p10, p90)})]` by increasing fraction (rounded to 2
    places), over cost_ratio, cost_s and the METRICS."""
    by_fraction = {}
    for r in records:
        by_fraction.setdefault(round(r["fraction"], 2), []).append(r)
    out = []
    for fraction, rows in sorted(by_fraction.items()):
        stats = {}
        for key in ("cost_ratio", "cost_s", *(m[0] for m in METRICS)):
            v = np.asarray([r[key] for r in rows if r[key] is not None], dtype=float)
            stats[key] = (float(np.median(v)), float(np.percentile(v, 10)), float(np.percentile(v, 90))) \
                if len(v) else (None, None, None)
        out.append((fraction, len(rows), stats))
    return out


def markdown(points):
    """The table of `summary`'s points: median (10th–90th percentile) of each column."""
    cell = lambda s, f: "—" if s[0] is None else f"{s[0]:{f}} ({s[1]:{f}}–{s[2]:{f}})"  # noqa: E731
    lines = ["| budget (× default iterations) | scenes | cost (× default run) | cost (s) | vel. err obs | "
             "vel. err fut | extrap − frozen (dB) |", "|---:|---:|---|---|---|---|---|"]
    for fraction, n, stats in points:
        lines.append(f"| {fraction:g} | {n} | {cell(stats['cost_ratio'], '.2f')} | {cell(stats['cost_s'], '.0f')} | "
                     f"{cell(stats['vel_obs'], '.3f')} | {cell(stats['vel_fut'], '.3f')} | "
                     f"{cell(stats['gain_frozen'], '+.2f')} |")
    return "\n".join(lines) + "\n"


def pareto_plot(points, path):
    """Write `path` (PNG): each metric's median (bars: 10th–90th percentile) against the median
    cost ratio, one point per budget, the budgets on the Pareto front joined."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(METRICS), figsize=(4.2 * len(METRICS), 3.8))
    xs = [stats["cost_ratio"][0] for _, _, stats in points]
    for ax, (key, label, sign) in zip(axes, METRICS):
        ys = [stats[key][0] for _, _, stats in points]
        low = [y - stats[key][1] for y, (_, _, stats) in zip(ys, points)]
        high = [stats[key][2] - y for y, (_, _, stats) in zip(ys, points)]
        pareto_panel(ax, xs, ys, [low, high], [f"{fraction:g}× ({n})" for fraction, n, _ in points], sign,
                     "training cost (× the default run's)", label)
    fig.suptitle("scene family, defaults: accuracy against training time (median, 10th–90th pct)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)


def pareto(out, plot=None, write=None):
    """`velogauss bench family pareto`: the table (returned, and written to `write` when given)
    and the plot (to `plot` when given). ValueError when no scene has its default run."""
    records = collect(out)
    if not records:
        raise ValueError(f"--out: no finished default run (random-SEED-full-s{RUN_SEED}/metrics.json) in {out}")
    points = summary(records)
    text = markdown(points)
    if plot is not None:
        pareto_plot(points, plot)
    if write is not None:
        write_text(write, text)
    return text
