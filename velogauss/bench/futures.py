"""What the choice of future is worth: every future a trained run offers, scored past its window.

A run's training fixes the model inside the window; its future (spec/motion.md, "The future past
the window") is a choice made after that, which this benchmark replays without retraining. For
each run folder, the model and its scene are loaded as `velogauss eval` loads them, and the
extrapolation split is rendered under each future of `FUTURES` (the spec's `future` set on the
loaded model; "fit" refitted by `velogauss.train.forecast.fit_forecast` with the run's seed, so a
run trained under "fit" gets its own forecast back). Per run and future: the mean PSNR of the
extrapolation frames, and for a generated scene the particle velocity's relative error past the
window (`velogauss.evaluate.velocity_error`, "future" mean). "hold" renders the model at the
window's end, which is the freeze baseline by definition (`velogauss.evaluate.freeze_baseline`),
so it is rendered once and is both.

Over a set of runs, each policy, a future applied to every run, then the run's own future ("as
trained") and the best future per run (an oracle: it reads the future frames), is summarised by
the spread of its extrapolation PSNR minus the run's freeze baseline (median, 10th percentile,
worst; `velogauss.bench.family.spread`) and the count of runs below the baseline.

  velogauss bench futures RUN [RUN ...] --write futures.md    (futures.json beside it)
"""

import dataclasses
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from velogauss.bench.family import spread
from velogauss.bench.harness import markdown_cell
from velogauss.io_utils import write_json, write_text

# The futures replayed, in the spec's order of "The future past the window".
FUTURES = ("hold", "coast", "integrate", "fit")
# A run's own future: what its spec says after training ("fit" holding its forecast, or what
# the forecast's backtest made it).
AS_TRAINED = "as trained"
ORACLE = "best per run (oracle)"


def score_run(run_dir):
    """The futures of the trained run at `run_dir` (module docstring): a JSON-ready dict with
    `run`, `data`, `max_time`, `trained` (the future its spec says, "fit" refitted as
    `fit_choice`), `frozen` (the freeze baseline's PSNR), and per future of `FUTURES` its
    `psnr` and `vel_future` (None without ground truth or velocity). FileNotFoundError naming a
    missing run folder or checkpoint (the scene's loader refuses one with nothing past its window)."""
    from velogauss.evaluate import evaluate_split, freeze_baseline, velocity_error
    from velogauss.run import ground_truth, load_run_model, load_run_scene, recorded_data_dir
    from velogauss.train.forecast import fit_forecast

    run_dir = Path(run_dir)
    model, cfg = load_run_model(run_dir, "cpu")
    scene = load_run_scene(cfg, recorded_data_dir(run_dir))
    truth = ground_truth(scene)
    trained = model.spec.future
    frozen = freeze_baseline(model, scene.extrapolation, scene.background, scene.max_time)["mean"]["psnr"]
    futures = {}
    fit_choice = None
    for future in FUTURES:
        model.spec = dataclasses.replace(model.spec, future=future)
        model.set_forecast(None)
        if future == "fit":
            fit_choice = fit_forecast(model, scene, cfg, np.random.default_rng(cfg.train.seed))["future"]
        psnr = frozen if future == "hold" else evaluate_split(
            model, scene.extrapolation, scene.background, with_lpips=False)["mean"]["psnr"]
        vel = None
        if truth is not None and model.has_velocity:
            vel = velocity_error(model, truth, scene.max_time)["future"]["relative_l2"]
        futures[future] = {"psnr": psnr, "vel_future": vel}
    return {"run": str(run_dir), "data": str(scene.root), "max_time": float(scene.max_time), "trained": trained,
            "fit_choice": fit_choice, "frozen": frozen, "futures": futures}


def gains(records):
    """{policy: [extrapolation PSNR − freeze baseline per run]}: each of `FUTURES`, "as trained" and
    the oracle (the largest of the futures' gains per run, "hold"'s 0 included)."""
    out = {future: [r["futures"][future]["psnr"] - r["frozen"] for r in records] for future in FUTURES}
    out[AS_TRAINED] = [r["futures"][r["trained"]]["psnr"] - r["frozen"] for r in records]
    out[ORACLE] = [max(r["futures"][f]["psnr"] for f in FUTURES) - r["frozen"] for r in records]
    return out


def markdown(records):
    """Per run, each future's gain over the freeze baseline; then each policy's spread over the runs."""
    table = gains(records)
    lines = ["## Each run under each future: extrapolation PSNR − freeze baseline (dB)", "",
             "| run | trained | fit refitted | frozen dB | " + " | ".join(FUTURES) + " | best |",
             "|---|---|---|---:|" + "---:|" * len(FUTURES) + "---|"]
    for i, r in enumerate(records):
        best = max(FUTURES, key=lambda f: r["futures"][f]["psnr"])
        lines.append(f"| {Path(r['run']).name} | {r['trained']} | {r['fit_choice']} | {r['frozen']:.2f} | "
                     + " | ".join(f"{table[f][i]:+.2f}" for f in FUTURES) + f" | {best} |")
    lines += ["", "## Each policy over the runs", "",
              "| policy | runs | median | 10th percentile | worst | runs below the freeze baseline |",
              "|---|---:|---:|---:|---:|---:|"]
    for policy in (AS_TRAINED, *FUTURES, ORACLE):
        n, median, p10, worst = spread(table[policy], "higher")
        below = sum(g < 0 for g in table[policy])
        lines.append(f"| {policy} | {n} | " + " | ".join(markdown_cell(s, "{:+.2f}") for s in (median, p10, worst))
                     + f" | {below} |")
    return "\n".join(lines) + "\n"


def run(run_dirs, write=None):
    """`velogauss bench futures`: score every run folder, return the Markdown; with `write`, also
    write it there and the records as JSON beside it (same stem), atomically."""
    if not run_dirs:
        raise ValueError("runs: expected at least one run folder")
    if write is not None and Path(write).suffix == ".json":
        raise ValueError(f"--write: the Markdown file, whose records go beside it as .json; got {write}")
    records = [score_run(r) for r in tqdm(run_dirs, desc="runs")]
    text = markdown(records)
    if write is not None:
        write = Path(write)
        write_json(write.with_suffix(".json"), {"runs": records})
        write_text(write, text)
    return text
