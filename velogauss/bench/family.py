"""The scene family's study: train the defaults on many random scenes and read how the motion
scores spread over them, per kind of motion and against the study's targets.

`velogauss bench family scenes --seeds tuning --out OUT` renders each seed's scene
(`velogauss.scenes.family.make_random_scene`) into `OUT/data/random-SEED/` and writes
`OUT/grid.toml`, a `velogauss sweep` grid of those folders under `ABLATIONS` with one training
seed (`RUN_SEED`); the sweep trains them into `OUT/random-SEED-ABLATION-s0/` (the run names of
velogauss/sweep/grid.py). `velogauss bench family table --out OUT` then reads each run's
metrics.json (`velogauss.evaluate.evaluate_model`'s result) into one row per scene:

- particle velocity relative error: `motion.velocity.observed.relative_l2` and
  `motion.velocity.future.relative_l2` (means over the evaluation times of each window);
- its split (`velogauss.evaluate`'s module docstring): the error of each body's mean motion,
  `translation_relative_l2`, and the scene's own `translation_only_relative_l2`, what moving
  each body with its true mean velocity and nothing else would score, observed and future;
- PSNR: `splits.interpolation.mean.psnr`, `splits.extrapolation.mean.psnr`, and the freeze
  baseline's `freeze_baseline.mean.psnr` (the last observed instant held still);
- the deform-only run's extrapolation PSNR: what the velocity field buys over a deformation
  network alone;
- the run folder's `motion_form.json` `choice` (`model.patterns = "auto"`), when written, marked
  "(held)" when its `future` is "hold", "(coast)" when "coast"; when "fit", the form that trained
  the window and the forecast that `forecast.json` says was fitted after it (`form_label`);
- the code that trained the full run (`velogauss.provenance.code_label`: its commit), "—" for a
  run trained before run folders recorded it, so a table that merges runs of several versions
  says which row is which.

`velogauss bench family translation-only --seeds S` scores each scene's own translation-only
velocity error from its drawn parameters (`translation_only`): the floor that the velocity
targets sit under when the bodies spin or change shape.

Then the distributions (over all scenes, and per kind of motion: a scene counts under each
kind of its moving bodies) and the targets, met or missed. Runs of `ABLATIONS` that have not
finished are listed as missing, never dropped; runs of other ablations are not read.
"""

import json
import os
from pathlib import Path
from typing import get_args

import numpy as np
import tomli_w
from tqdm.auto import tqdm

from velogauss.bench.harness import markdown_cell
from velogauss.io_utils import write_text
from velogauss.provenance import code_label
from velogauss.scenes.family import (KINDS, REPORT_SEEDS, TUNING_SEEDS, draw_parameters, make_random_scene,
                                     scene_from_parameters)
from velogauss_core.motion import Ablation

SEED_LISTS = {"tuning": TUNING_SEEDS, "report": REPORT_SEEDS}
# The defaults, and a model without a velocity field: the gap between them is what the physics buys.
ABLATIONS = ("full", "deform-only")
# The form column's mark of a run's future other than the form's own law (model.future; "fit" is
# spelt out by `form_label`).
FUTURE_LABELS = {"hold": " (held)", "coast": " (coast)"}
# The form column's name of a forecast's future (forecast.json, spec/motion.md, "The future past the window").
FORECAST_LABELS = {"hold": "held", "integrate": "mlp"}
# One training seed per scene: the spread studied is the scenes', not the optimiser's.
RUN_SEED = 0
# numpy.percentile's method: linear interpolation between the order statistics.
PERCENTILE_METHOD = "linear"

# (key, header, format) of the per-scene table's numeric columns.
COLUMNS = (
    ("vel_obs", "vel. err obs", "{:.3f}"), ("vel_fut", "vel. err fut", "{:.3f}"),
    ("trans_obs", "of it translation, obs", "{:.3f}"), ("trans_fut", "of it translation, fut", "{:.3f}"),
    ("only_obs", "translation-only, obs", "{:.3f}"), ("only_fut", "translation-only, fut", "{:.3f}"),
    ("interp", "interp PSNR", "{:.2f}"), ("extrap", "extrap PSNR", "{:.2f}"), ("frozen", "frozen PSNR", "{:.2f}"),
    ("gain_frozen", "extrap − frozen", "{:+.2f}"), ("deform_extrap", "deform-only extrap", "{:.2f}"),
    ("gain_deform", "extrap − deform-only", "{:+.2f}"),
)
# (key, label, which way is better) of the distributed scores.
SPREAD = (
    ("vel_obs", "vel. err obs", "lower"), ("vel_fut", "vel. err fut", "lower"),
    ("trans_obs", "vel. err obs, translation part", "lower"), ("trans_fut", "vel. err fut, translation part", "lower"),
    ("only_obs", "translation-only model's vel. err obs", "lower"),
    ("only_fut", "translation-only model's vel. err fut", "lower"),
    ("gain_frozen", "extrap − frozen (dB)", "higher"), ("gain_deform", "extrap − deform-only (dB)", "higher"),
)
BETTER = {key: better for key, _, better in SPREAD}
# The study's targets over all scenes: (label, key, statistic, comparison, bound). Velocity within
# a few per cent where it was seen and within ten where it was not; extrapolation clearly better
# than freezing the last frame and than a deformation network without physics.
TARGETS = (
    ("median vel. err obs", "vel_obs", "median", "≤", 0.05),
    ("median vel. err fut", "vel_fut", "median", "≤", 0.10),
    ("90th pct vel. err fut", "vel_fut", "p90", "≤", 0.25),
    ("median extrap − frozen (dB)", "gain_frozen", "median", "≥", 6.0),
    ("median extrap − deform-only (dB)", "gain_deform", "median", "≥", 3.0),
)


def parse_seeds(text):
    """The seeds of `--seeds`: `tuning`, `report` (family.py's lists) or comma-separated integers
    ≥ 0, duplicates dropped; ValueError naming `--seeds` otherwise."""
    if text in SEED_LISTS:
        return SEED_LISTS[text]
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise ValueError(f"--seeds: expected tuning, report or comma-separated integers >= 0, got {text!r}")
    return tuple(dict.fromkeys(seeds))


def make_scenes(seeds, out, echo=print):
    """Render each seed's scene into `out/data/random-SEED/` unless it holds scene.json (written
    last, so a folder without it is an interrupted render and is rendered again); return the folders."""
    folders = []
    for seed in seeds:
        folder = Path(out) / "data" / f"random-{seed}"
        if not (folder / "scene.json").is_file():
            echo(f"generating random scene {seed} into {folder}")
            make_random_scene(seed, folder)
        folders.append(folder)
    return folders


def settings(ablations, overrides):
    """`overrides` (["section.key=value"]) as `{key: value}`, each value as the training config
    reads it; ValueError naming the override or the ablation that the config rejects."""
    from velogauss.config import config_to_dict
    from velogauss.run import build_config

    if not ablations or not set(ablations) <= set(get_args(Ablation)):
        raise ValueError(f"--ablations: expected some of {', '.join(get_args(Ablation))}, got {', '.join(ablations)}")
    for ablation in ablations:
        build_config(None, [f"model.ablation={ablation}", *overrides])
    values = {}
    for override in overrides:
        key = override.partition("=")[0].strip()
        section, _, name = key.partition(".")
        values[key] = config_to_dict(build_config(None, [override]))[section][name]
    return values


def write_grid(out, folders, ablations=ABLATIONS, values=None):
    """Write `out/grid.toml`, the sweep of `folders` × `ablations` at `RUN_SEED`, one thread per
    run, with `values` ({"section.key": value}) as its `[set]`; return its path.

    `data` is relative to the grid file, as velogauss/sweep/grid.py reads it; `out` is absolute,
    since the sweep reads it relative to where it is started."""
    out = Path(out).resolve()
    grid = {"data": [str(Path(f).resolve().relative_to(out)) for f in folders], "ablations": list(ablations),
            "seeds": [RUN_SEED]}
    doc = {"out": str(out), "threads": 1, **({"set": values} if values else {}), "grid": [grid]}
    path = out / "grid.toml"
    write_text(path, "# Written by `velogauss bench family scenes`: the family study's training runs.\n"
                     + tomli_w.dumps(doc))
    return path


def scenes(seeds, out, ablations=ABLATIONS, overrides=(), echo=print):
    """`velogauss bench family scenes`: the scenes and their grid (the settings checked before
    any scene is rendered); echoes the sweep command to run next and returns the grid's path."""
    values = settings(tuple(ablations), tuple(overrides))
    folders = make_scenes(parse_seeds(seeds), out, echo)
    path = write_grid(out, folders, ablations, values)
    echo(f"grid: {path}\nnext: velogauss sweep {path} --cpus {os.cpu_count()}")
    return path


def translation_only(seeds):
    """`[(seed, kinds, observed, future)]`: each seed's scene's own translation-only velocity
    score (`velogauss.evaluate`'s `translation_only_relative_l2`: what moving every body with its
    true mean velocity, without spin or change of shape, scores), from its drawn parameters
    alone: nothing is rendered or trained."""
    from velogauss.evaluate import TrueMotion, velocity_error

    rows = []
    for seed in tqdm(seeds, desc="translation-only", leave=False):
        params = draw_parameters(seed)
        scene = scene_from_parameters(params)
        error = velocity_error(TrueMotion(scene), scene, params["max_time"])
        rows.append((seed, tuple(params["kinds"]), *(error[w]["translation_only_relative_l2"]
                                                    for w in ("observed", "future"))))
    return rows


def translation_only_markdown(rows):
    """`translation_only`'s rows as Markdown: per scene, then the spread over the scenes and how
    many reach the velocity targets' bounds (TARGETS) with translation alone."""
    lines = ["| seed | kinds | translation-only, obs | translation-only, fut |", "|---:|---|---:|---:|"]
    lines += [_row([seed, ", ".join(kinds), markdown_cell(obs, "{:.3f}"), markdown_cell(fut, "{:.3f}")])
              for seed, kinds, obs, fut in rows]
    bounds = {key: bound for _, key, statistic, _, bound in TARGETS if statistic == "median"}
    lines += ["", "| window | n | median | p90 | worst | scenes at or under the target's bound |", "|---|---:|---:|---:|---:|---:|"]
    for column, window, key in ((2, "observed", "vel_obs"), (3, "future", "vel_fut")):
        values = [r[column] for r in rows]
        n, *stats = spread(values, "lower")
        reached = sum(v is not None and v <= bounds[key] for v in values)
        lines.append(_row([window, n, *(markdown_cell(x, "{:.3f}") for x in stats), f"{reached} (≤ {bounds[key]:g})"]))
    return "\n".join(lines) + "\n"


def run_folder(out, scene, ablation):
    """`out/<scene>-<ablation>-s<RUN_SEED>`: where the grid's sweep trains that point."""
    return Path(out) / f"{scene}-{ablation}-s{RUN_SEED}"


def collect(out):
    """`(rows, missing)`: one row per scene under `out/data` whose full run finished (sorted by
    seed), and the run folders whose metrics.json is absent."""
    found = []
    for path in Path(out, "data").glob("*/scene.json"):
        scene = json.loads(path.read_text())
        if "family" not in scene:
            raise ValueError(f"{path}: not a scene of the random family (no `family` entry)")
        found.append((scene["family"]["seed"], path.parent.name, scene))
    rows, missing = [], []
    for _, name, scene in sorted(found, key=lambda f: f[:2]):
        runs = {a: run_folder(out, name, a) for a in ABLATIONS}
        missing += [r for r in runs.values() if not (r / "metrics.json").is_file()]
        if (runs["full"] / "metrics.json").is_file():
            rows.append(scene_row(scene, runs["full"], runs["deform-only"]))
    return rows, missing


def form_label(report, forecast):
    """The form column of a run from its motion_form.json and forecast.json dicts ({} when absent):
    the backtest's choice, with a held or coasting future marked (part of what the run chose);
    where the future was fitted after training ("fit", spec/motion.md, "Choosing the form"), the
    patterns that trained the window and the forecast: "mlp, forecast rigid". None: no choice."""
    if "choice" not in report:
        return None
    if report.get("future") != "fit":
        return report["choice"] + FUTURE_LABELS.get(report.get("future"), "")
    fitted = FORECAST_LABELS.get(forecast.get("future"), forecast.get("choice", "—"))
    return f"{report['patterns']}, forecast {fitted}"


def scene_row(scene, full_run, deform_run):
    """One scene's row from its scene.json dict and its runs' folders (the deform-only may be absent)."""
    metrics = json.loads((full_run / "metrics.json").read_text())
    params = scene["family"]["parameters"]
    extrap = _at(metrics, "splits", "extrapolation", "mean", "psnr")
    frozen = _at(metrics, "freeze_baseline", "mean", "psnr")
    deform = deform_run / "metrics.json"
    deform_extrap = _at(json.loads(deform.read_text()), "splits", "extrapolation", "mean", "psnr") \
        if deform.is_file() else None
    form = form_label(*(json.loads(path.read_text()) if path.is_file() else {}
                        for path in (full_run / "motion_form.json", full_run / "forecast.json")))
    return {"seed": scene["family"]["seed"], "kinds": tuple(params["kinds"]), "rig": params["rig"],
            "px": scene["generator"]["resolution"][0], "frames": scene["generator"]["n_times"],
            "vel_obs": _at(metrics, "motion", "velocity", "observed", "relative_l2"),
            "vel_fut": _at(metrics, "motion", "velocity", "future", "relative_l2"),
            **{f"{short}_{window[:3]}": _at(metrics, "motion", "velocity", window, key)
               for short, key in (("trans", "translation_relative_l2"), ("only", "translation_only_relative_l2"))
               for window in ("observed", "future")},
            "interp": _at(metrics, "splits", "interpolation", "mean", "psnr"), "extrap": extrap, "frozen": frozen,
            "gain_frozen": _difference(extrap, frozen), "deform_extrap": deform_extrap,
            "gain_deform": _difference(extrap, deform_extrap),
            "form": form, "code": code_label(full_run)}


def _at(tree, *keys):
    """`tree[k1][k2]...`, or None where a level is missing or None."""
    for key in keys:
        tree = tree.get(key) if isinstance(tree, dict) else None
    return tree


def _difference(a, b):
    return None if a is None or b is None else a - b


def spread(values, better):
    """`(n, median, p90, worst)` of the non-None `values`: p90 is the value 90 % of them do at
    least as well as (the 90th percentile where lower is better, the 10th where higher is),
    worst the largest or the smallest; the statistics are None when there are no values."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    if not len(v):
        return 0, None, None, None
    q, worst = (90, v.max()) if better == "lower" else (10, v.min())
    return len(v), float(np.median(v)), float(np.percentile(v, q, method=PERCENTILE_METHOD)), float(worst)


def groups(rows):
    """`[(name, rows)]`: all scenes, then each kind of motion (family.py's order) that a scene's
    moving bodies have."""
    kinds = [k for k in KINDS if k != "still" and any(k in r["kinds"] for r in rows)]
    return [("all", rows)] + [(k, [r for r in rows if k in r["kinds"]]) for k in kinds]


def targets(rows):
    """`[(label, value, status)]`: each of `TARGETS` over all scenes, then the count of scenes
    whose extrapolation is below the freeze baseline (target 0); status "met", "missed" or
    "no data"."""
    results = []
    for label, key, statistic, comparison, bound in TARGETS:
        by_name = dict(zip(("n", "median", "p90", "worst"), spread([r[key] for r in rows], BETTER[key])))
        value = by_name[statistic]
        met = None if value is None else (value <= bound if comparison == "≤" else value >= bound)
        results.append((f"{label} {comparison} {bound:g}", value, _status(met)))
    gains = [r["gain_frozen"] for r in rows if r["gain_frozen"] is not None]
    below = sum(g < 0 for g in gains)
    met = below == 0 if gains else None
    results.append(("scenes with extrap < frozen = 0", below if gains else None, _status(met)))
    return results


def _status(met):
    return "no data" if met is None else ("met" if met else "missed")


def markdown(out, rows, missing):
    """The study's Markdown: the scenes, the distributions, the targets, the missing runs."""
    headers = ["seed", "kinds", "rig", "px", "frames", *(h for _, h, _ in COLUMNS), "motion form", "code"]
    lines = [f"# Scene family study: {out}", "",
             f"{len(rows)} scene(s) with a finished full run; {len(missing)} run(s) missing (listed at the end).",
             "", "## Scenes", "", _row(headers), "|---:|---|---|" + "---:|" * (2 + len(COLUMNS)) + "---|---|"]
    for r in rows:
        lines.append(_row([r["seed"], ", ".join(r["kinds"]), r["rig"], r["px"], r["frames"],
                           *(markdown_cell(r[k], fmt) for k, _, fmt in COLUMNS), r["form"] or "—",
                           r["code"] or "—"]))
    lines += ["", "## Distribution", "",
              f"Percentiles by numpy.percentile, method=\"{PERCENTILE_METHOD}\" (linear interpolation between "
              "the order statistics). p90: the value 90 % of the scenes do at least as well as (the 90th "
              "percentile of an error, the 10th of a dB gain); worst: the largest error, the smallest gain. "
              "A scene counts under each kind of motion its moving bodies have.", "",
              _row(["motion", "metric", "n", "median", "p90", "worst"]), "|---|---|---:|---:|---:|---:|"]
    for name, members in groups(rows):
        for key, label, better in SPREAD:
            n, *stats = spread([r[key] for r in members], better)
            lines.append(_row([name, label, n, *(markdown_cell(s, "{:.3f}") for s in stats)]))
    lines += ["", "## Targets", "", _row(["target", "value", "status"]), "|---|---:|---|"]
    for label, value, status in targets(rows):
        lines.append(_row([label, markdown_cell(value, "{:d}" if isinstance(value, int) else "{:.3f}"), status]))
    lines += ["", "## Missing runs", ""] + ([f"- {m} (no metrics.json)" for m in missing] or ["none"])
    return "\n".join(lines) + "\n"


def _row(cells):
    return "| " + " | ".join(str(c) for c in cells) + " |"


def table(out, write=None):
    """`velogauss bench family table`: the study's Markdown for `out` (also into `write`, atomically)."""
    data = Path(out, "data")
    if not data.is_dir():
        raise FileNotFoundError(2, "no scenes folder (run `velogauss bench family scenes` first)", str(data))
    text = markdown(out, *collect(out))
    if write is not None:
        write_text(write, text)
    return text
