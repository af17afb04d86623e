"""The run folder: what the commands read from and write into it, and the config it records.

Every command writes into one run folder (`runs/<scene>-<YYYYmmdd-HHMMSS>` by default):
`config.toml`, `checkpoints/`, `log.jsonl` (training), `metrics.json`, `metrics.md`
(`velogauss eval`), `renders/` (`velogauss render`), `export/` (`velogauss export`).
Results are written atomically (`velogauss.io_utils`). Bad input raises `ValueError` or
`OSError` naming the flag, file or value; the command line turns it into one error line
(`velogauss.errors`).

The commands of `velogauss.cli`, `velogauss.sweep` and `velogauss.view` share these helpers;
torch and the model load only inside the functions that need them, so importing this module
is cheap.
"""

import contextlib
import dataclasses
import datetime
import json
import shutil
from pathlib import Path

from velogauss.config import load_config
from velogauss.provenance import PROVENANCE_FILE

BACKGROUNDS = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0)}
# A folder with any of these is a run (velogauss.train.loop writes them), and a new run or a
# failed one removes them all, so that no report of an earlier run stays beside it.
RUN_FILES = ("config.toml", "log.jsonl", "checkpoints", "motion_form.json", "forecast.json", PROVENANCE_FILE)
# What `train --overwrite` removes: the run and what eval, render and export wrote into it;
# data/ stays, since it may be the very scene being trained on.
RUN_OUTPUTS = RUN_FILES + ("metrics.json", "metrics.md", "renders", "export", "sequence")


# --- the config of a run ---------------------------------------------------------------

def train_flags(effects=None, ablation=None, iterations=None, max_time=None, half_res=None, background=None,
                device=None, threads=None, data_format=None):
    """The config values the `train` flags given stand for: {"section.key": (flag, value)}
    (flags left at None are not given). Raises ValueError naming `--background` when malformed.
    """
    pairs = {
        "model.effects": ("--effects", None if effects is None else
                          effects.strip() if effects.strip() == "declared" else [e.strip() for e in effects.split(",")]),
        "model.ablation": ("--ablation", ablation),
        "train.iterations": ("--iterations", iterations),
        "data.format": ("--format", data_format),
        "data.max_time": ("--max-time", max_time),
        "data.half_res": ("--half-res", half_res),
        "data.background": ("--background", None if background is None else parse_background(background)),
        "train.device": ("--device", device),
        "train.threads": ("--threads", threads),
    }
    return {key: pair for key, pair in pairs.items() if pair[1] is not None}


def parse_background(text):
    """`white`, `black` or `R,G,B` (each in [0, 1]) → an RGB tuple; ValueError naming `--background`."""
    if text.lower() in BACKGROUNDS:
        return BACKGROUNDS[text.lower()]
    try:
        rgb = tuple(float(v) for v in text.split(","))
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(0.0 <= v <= 1.0 for v in rgb):
        raise ValueError(f"--background: expected white, black or R,G,B with values in [0, 1], got {text!r}")
    return rgb


def build_config(path, overrides, flags=None):
    """The training config: defaults, then the TOML file `path` (if any), then `overrides`
    (["section.key=value"]), then the train `flags` (as `train_flags` returns them)."""
    if path is not None:
        existing_file(path, "config file")
    return load_config(path, overrides, flags)


def with_data_dir(cfg, data_dir):
    """`cfg` with the scene folder recorded (absolute), so `eval` and `render` find it again."""
    return dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dir=str(Path(data_dir).resolve())))


def recorded_data_dir(run_dir):
    """The scene folder a run was trained on, from `RUN_DIR/config.toml`."""
    cfg = load_config(existing_file(Path(run_dir) / "config.toml", "run config"))
    if not cfg.data.dir:
        raise ValueError(f"{Path(run_dir) / 'config.toml'}: data.dir: empty; pass the scene folder with --data")
    return Path(cfg.data.dir)


def check_device(name, what="--device"):
    """Raise ValueError naming `what`, `name` and the devices this machine has, unless torch
    can use device `name` here (cpu, cuda[:i], mps)."""
    import torch

    cuda = torch.cuda.device_count() if torch.cuda.is_available() else 0
    mps = torch.backends.mps.is_available()
    available = ["cpu"] + [f"cuda:{i}" for i in range(cuda)] + ["mps"] * mps
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        device = None
    ok = device is not None and (device.type == "cpu" or (device.type == "cuda" and (device.index or 0) < cuda)
                                 or (device.type == "mps" and mps))
    if not ok:
        raise ValueError(f"{what}: device {name!r} is not available on this machine; available: {', '.join(available)}")


def default_device():
    """cuda when torch sees a GPU, else cpu."""
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


# --- the folder ------------------------------------------------------------------------

def default_run_dir(scene_name, now=None):
    """`runs/<scene>-<YYYYmmdd-HHMMSS>` (local time)."""
    stamp = (now or datetime.datetime.now()).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{scene_name}-{stamp}"


def existing_file(path, what):
    """`path` as a Path; FileNotFoundError saying `what` is missing unless it is a file."""
    if not Path(path).is_file():
        raise FileNotFoundError(2, f"{what} not found", str(path))
    return Path(path)


def refuse_existing_run(run_dir):
    """ValueError naming `run_dir` and what it holds when it already holds a run."""
    found = [name for name in RUN_FILES if (Path(run_dir) / name).exists()]
    if found:
        raise ValueError(f"{run_dir}: already holds a run ({', '.join(found)}); continue it with --resume, "
                         "choose a new --out, or pass --overwrite to replace it")


def remove_run(run_dir, names=RUN_OUTPUTS):
    """Remove the files and folders `names` of `run_dir` (those that exist)."""
    for name in names:
        path = Path(run_dir) / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


@contextlib.contextmanager
def no_half_made_run(run_dir, fresh):
    """On any failure before the first checkpoint of a new run, remove what it created: the
    whole folder when it did not exist before, else the run files written into it."""
    from velogauss.train.checkpoint import checkpoint_path

    existed = Path(run_dir).exists()
    try:
        yield
    except BaseException:
        if fresh and not checkpoint_path(run_dir).is_file():
            if not existed:
                shutil.rmtree(run_dir, ignore_errors=True)
            else:
                remove_run(run_dir, RUN_FILES)
        raise


# --- what the commands load and write --------------------------------------------------

def load_run_model(run_dir, device=None):
    """`(model, cfg)` of a trained run, without gradients; FileNotFoundError naming the missing
    folder or checkpoint, ValueError naming `--device` when this machine lacks it."""
    run_dir = Path(run_dir)
    if device is not None:
        check_device(device)
    if not run_dir.is_dir():
        raise FileNotFoundError(2, "run folder not found", str(run_dir))
    existing_file(run_dir / "checkpoints" / "latest.pt", "no checkpoint in the run folder (train it first)")
    from velogauss.threads import apply_threads
    from velogauss.train.checkpoint import load_model

    model, cfg = load_model(run_dir, device or default_device())
    apply_threads(cfg.train.threads)
    return model, cfg


def load_run_scene(cfg, data_dir):
    """The run's scene, loaded with the run's split, observed window, resolution and background; DataError
    for bad data or images smaller than the SSIM window."""
    from velogauss.data import check_trainable_size, load_scene

    scene = load_scene(data_dir, max_time=cfg.data.max_time, half_res=cfg.data.half_res,
                       background=cfg.data.background, split=cfg.data.split, format=cfg.data.format,
                       heldout_cameras=cfg.data.heldout_cameras)
    check_trainable_size(scene)
    return scene


def run_evaluation(run_dir, model, scene, splits, lpips_weights):
    """Evaluate, write `run_dir/metrics.json` and `run_dir/metrics.md` atomically; return the result,
    which names the code that trained the run (`velogauss.provenance.code_label`) beside it."""
    from velogauss.evaluate import evaluate_model, metrics_markdown
    from velogauss.io_utils import write_json, write_text
    from velogauss.provenance import code_label

    result = {"run": str(run_dir), "trained_by": code_label(run_dir), "data": str(scene.root),
              **evaluate_model(model, scene, splits, lpips_weights, ground_truth(scene), progress=True)}
    write_json(Path(run_dir) / "metrics.json", result)
    write_text(Path(run_dir) / "metrics.md", metrics_markdown(result, title=f"Metrics of {Path(run_dir).name}"))
    return result


def run_render(out_dir, model, scene, fps=8.0, label=True):
    """Write the pictures of `velogauss.visualize.render_run`; return their paths."""
    from velogauss.visualize import render_run

    return render_run(model, scene, out_dir, fps=fps, ground_truth=ground_truth(scene), label=label, progress=True)


def motion_form_line(run_dir):
    """What the backtest chose for the run in `run_dir` (its motion_form.json) as one line, or None
    when the run chose nothing (its form was set, or the run is static)."""
    path = Path(run_dir) / "motion_form.json"
    if not path.is_file():
        return f"forecast: {forecast_phrase(run_dir)}" if (Path(run_dir) / "forecast.json").is_file() else None
    report = json.loads(path.read_text())
    if "reason" in report:  # chosen without a backtest (velogauss.train.backtest.nothing_to_forecast)
        return f"motion form: {report['choice']} ({report['reason']})"
    scores = report.get("scores", {}).get(report["choice"])
    scored = "" if not scores else " (tail scores " + " / ".join(f"{x:.2f}" for x in scores) + "; 1 = freezing)"
    future = {"hold": "the future holds: no form predicted the held-out tails better than freezing the motion",
              "coast": "the motion coasts past the window: its patterns keep their value at the window's end",
              "fit": forecast_phrase(run_dir)}.get(report.get("future"), "the motion is integrated past the window")
    if report.get("patterns", report["choice"]) != report["choice"]:
        window = report["window_psnr"]
        future = (f"a probe trained with it reconstructs the window at {window[report['choice']]:.2f} dB against the "
                  f"time network's {window['mlp']:.2f}, so the time network trains the window; {future}")
    elif "first_scores" in report:  # the window was the time network's, the oscillators reconstruct it better
        window = report["window_psnr"]
        first = report.get("first_choice", "mlp")
        future = (f"the first probe's paths chose {'the time network' if first == 'mlp' else first}, but a probe "
                  f"with the oscillators reconstructs the window at {window['harmonic']:.2f} dB against the time "
                  f"network's {window['mlp']:.2f}, and the scores are of the oscillators' own paths; {future}")
    return f"motion form: {report['choice']}{scored}; {future}"


def forecast_phrase(run_dir):
    """What the forecast fitted at the end of training (forecast.json) did, as a clause."""
    path = Path(run_dir) / "forecast.json"
    if not path.is_file():
        return "past the window, a form fitted to the trained paths (at the end of training)"
    report = json.loads(path.read_text())
    return {"hold": "past it, the future holds: on the trained paths no form beat freezing the motion",
            "integrate": "past it, the time network carries on: on the trained paths it forecast best"}.get(
        report["future"], f"past it, {report['choice']} fitted to the trained paths carries the Gaussians on")


def headline(result, run_dir):
    """The metrics' summary and where the full tables are, as the commands print them."""
    from velogauss.evaluate import summary_markdown

    return f"\n{summary_markdown(result)}\nmetrics: {Path(run_dir) / 'metrics.md'} and metrics.json"


def ground_truth(scene):
    """The analytic scene of a generated scene folder, None for recorded data."""
    from velogauss.scenes import load_ground_truth

    return load_ground_truth(scene.root) if scene.metadata and "scene" in scene.metadata else None
