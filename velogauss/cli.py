"""The `velogauss` command: make a synthetic scene, train, evaluate, render, export, benchmark.

Every command writes into one run folder (`runs/<scene>-<YYYYmmdd-HHMMSS>` by default):
`config.toml`, `checkpoints/`, `log.jsonl` (training), `metrics.json`, `metrics.md`
(`velogauss eval`), `renders/` (`velogauss render`), `export/` (`velogauss export`).
Results are written atomically (`velogauss.io_utils`).

Bad input -- a missing run folder, checkpoint or image, a malformed scene file, an unknown
`--set` key, a bad value, a device this machine lacks, an output folder that cannot be written
or a full disk -- prints one line `error: <what is wrong, naming the file, field or value>`
and exits with code 2. Only the command-line boundary catches these errors (`DataError`,
`ValueError`, `OSError`); anything else is a bug and keeps its traceback. Outputs are checked
for writability before any work starts. Ctrl-C during training prints where the checkpoint
is and exits with code 130.

Threads (velogauss.threads): one torch thread, one compositing thread per available core and
OpenMP's passive wait policy, unless `--threads N` (config `train.threads`) or the
environment (OMP_WAIT_POLICY, OMP_NUM_THREADS) says otherwise.
"""

import contextlib
import datetime
import importlib
import inspect
import shutil
from pathlib import Path
from typing import List, Optional

import typer

from velogauss.threads import prepare_environment

# Before anything imports torch: libgomp reads its wait policy once, when it loads.
prepare_environment()

from velogauss.config import EFFECTS, Ablation, load_config  # noqa: E402
from velogauss.data import DataError  # noqa: E402
from velogauss.io_utils import check_writable  # noqa: E402
from velogauss.sweep.command import sweep_command  # noqa: E402
from velogauss.view.command import view_command  # noqa: E402

app = typer.Typer(
    name="velogauss",
    help="VeloGauss: 3D Gaussians moved by a learned, physically constrained velocity field.\n\n"
         "Main job: `velogauss train` generates the default synthetic scene, trains on it, "
         "evaluates interpolation and extrapolation, and renders the results.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # the shell's code for a process ended by SIGINT
BACKGROUNDS = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0)}
SPLIT_CHOICES = {"interp": ("interpolation",), "extrap": ("extrapolation",), "both": ("interpolation", "extrapolation")}

_CONFIG_HELP = "TOML config file; its values override the defaults."
_SET_HELP = "Override one config value, KEY=VALUE (e.g. train.iterations=300); repeatable; wins over --config."
_DEVICE_HELP = "Torch device: cpu, cuda, cuda:1 ... (default: the run's config)."
_LPIPS_HELP = ("Folder with the LPIPS weights alex.npz and vgg.npz (default: $VELOGAUSS_LPIPS_DIR, "
               "then ../shared/data/lpips beside the checkout, then the standard download).")


@contextlib.contextmanager
def user_errors():
    """Turn bad-input exceptions into one `error: ...` line on stderr and exit code 2."""
    try:
        yield
    except OSError as err:  # FileNotFoundError, a read-only or full disk: name the path
        where = f": {err.filename}" if err.filename else ""
        _fail(f"{err.strerror or err}{where}")
    except (DataError, ValueError) as err:
        _fail(str(err))


def _fail(message):
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(EXIT_BAD_INPUT)


# --- make-scene ------------------------------------------------------------------------

@app.command("make-scene")
def make_scene_command(
    name: Optional[str] = typer.Argument(None, help="Scene name (see --list)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output folder [default: data/NAME]."),
    resolution: int = typer.Option(128, help="Image width and height in pixels."),
    views: int = typer.Option(8, help="Number of cameras on the ring (2 of them held out for evaluation)."),
    times: int = typer.Option(21, help="Number of time steps in [0, 1]."),
    seed: int = typer.Option(0, help="Seed of the camera placement and point cloud."),
    monocular: bool = typer.Option(False, "--monocular", help="One train camera per time step (D-NeRF style)."),
    list_scenes: bool = typer.Option(False, "--list", help="List the scenes and their physical effects, then exit."),
):
    """Render a synthetic physics scene to disk in the D-NeRF layout (with ground truth in scene.json)."""
    from velogauss.scenes import DEFAULT_SCENE, SCENES, make_scene

    if list_scenes:
        typer.echo(scene_listing(SCENES, DEFAULT_SCENE))
        return
    with user_errors():
        if name is None:
            raise ValueError(f"NAME: missing scene name; choose one of {', '.join(SCENES)} (see --list)")
        out = out or Path("data") / name
        path = make_scene(name, out, resolution=resolution, n_views=views, n_times=times, seed=seed,
                          layout="monocular" if monocular else "multiview")
    typer.echo(f"wrote scene {name!r} to {path}")


def scene_listing(scenes, default):
    """One line per scene: name, effects, compressibility and what moves (its builder's docstring)."""
    lines = []
    for key, build in scenes.items():
        scene = build()
        doc = (inspect.getdoc(build) or "").splitlines()[0]
        tag = " (default)" if key == default else ""
        kind = "incompressible" if scene.incompressible else "compressible"
        lines.append(f"{key + tag:<18} effects: {', '.join(scene.effects):<34} {kind:<15} {doc}")
    return "\n".join(lines)


# --- train -----------------------------------------------------------------------------

@app.command("train")
def train_command(
    data_dir: Optional[Path] = typer.Argument(
        None, help="Scene folder (D-NeRF/NVFi layout). Omitted: generate the default synthetic scene into RUN_DIR/data."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder [default: runs/<scene>-<YYYYmmdd-HHMMSS>]."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help=_CONFIG_HELP),
    set_: List[str] = typer.Option([], "--set", "-s", help=_SET_HELP),
    scene: Optional[str] = typer.Option(None, help="Synthetic scene to generate when DATA_DIR is omitted [default: the default scene]."),
    effects: Optional[str] = typer.Option(
        None, help=f"Comma-separated effects the motion model may use: {','.join(EFFECTS)}."),
    ablation: Optional[Ablation] = typer.Option(None, help="Which of the paper's components to switch off."),
    iterations: Optional[int] = typer.Option(None, help="Training iterations; the schedule's \"auto\" keys (warm-up, "
                                                         "curriculum, physics ramp, densification) scale with them."),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the run in --out from its latest checkpoint; only train.iterations, "
                                 "train.device, train.threads, train.eval_every, train.checkpoint_every and data.dir "
                                 "may change."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Start a new run in an --out that already holds one, "
                                                              "replacing its config, log and checkpoint."),
    max_time: Optional[float] = typer.Option(None, help="End of the observed window; later frames are the future [default 0.75]."),
    half_res: Optional[bool] = typer.Option(None, "--half-res/--full-res", help="Halve the image resolution."),
    background: Optional[str] = typer.Option(None, help="white | black | R,G,B in [0, 1]."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
    threads: Optional[int] = typer.Option(
        None, help="CPU threads for torch and the compositing kernels; 0: one torch thread and one compositing "
                   "thread per available core, which holds up best when other processes share the cores "
                   "[default: the config's train.threads, 0]."),
    evaluate: bool = typer.Option(True, "--eval/--no-eval", help="Evaluate and render after training."),
    lpips_weights: Optional[Path] = typer.Option(None, help=_LPIPS_HELP),
):
    """Train VeloGauss on a scene, then evaluate interpolation and extrapolation and render the results.

    --out must be a new folder (or one without a run) unless --resume continues the run in it
    or --overwrite replaces it."""
    from velogauss.scenes import DEFAULT_SCENE

    with user_errors():
        flags = train_flags(effects=effects, ablation=ablation, iterations=iterations, max_time=max_time,
                            half_res=half_res, background=background, device=device, threads=threads)
        cfg_source = config
        if resume and overwrite:
            raise ValueError("--resume and --overwrite: choose one (continue the run, or replace it)")
        if resume:
            if out is None:
                raise ValueError("--resume: needs --out RUN_DIR, the run to continue")
            cfg_source = config or _existing_file(out / "config.toml", "run config")
        if data_dir is not None and not data_dir.is_dir():
            raise FileNotFoundError(2, "scene folder not found", str(data_dir))
        scene_name = scene or DEFAULT_SCENE
        run_dir = out or default_run_dir(data_dir.name if data_dir is not None else scene_name)
        if not resume and not overwrite:
            _refuse_existing_run(run_dir)
        if data_dir is None and scene is None and resume:
            data_dir = recorded_data_dir(run_dir)
        cfg = build_config(cfg_source, set_, flags)
        check_device(cfg.train.device, "train.device")
        check_writable(run_dir)
        if overwrite:
            _remove_run(run_dir)
    with user_errors(), _no_half_made_run(run_dir, fresh=not resume):
        if data_dir is None:
            data_dir = run_dir / "data"
            if not (data_dir / "transforms_train.json").is_file():
                typer.echo(f"generating synthetic scene {scene_name!r} into {data_dir}")
                _make_default_scene(scene_name, data_dir)
        cfg = with_data_dir(cfg, data_dir)
        data = load_run_scene(cfg, data_dir)
        typer.echo(f"training on {data_dir} ({len(data.train)} train frames) -> {run_dir}")
        from velogauss.train.loop import train

        try:
            model = train(cfg, data, run_dir, resume=resume, progress=True)
        except KeyboardInterrupt as err:
            typer.secho(str(err) or "training interrupted", err=True, fg=typer.colors.YELLOW)
            raise typer.Exit(EXIT_INTERRUPTED) from None
    if not evaluate:
        typer.echo(f"run folder: {run_dir}")
        return
    with user_errors():
        _eval_and_render(run_dir, model, cfg, data, lpips_weights)


# What a run folder holds (velogauss.train.loop): a folder with any of these is a run.
_RUN_FILES = ("config.toml", "log.jsonl", "checkpoints")
# What `--overwrite` removes before training: the run and what eval, render and export wrote
# into it. The scene folder (data/) stays: it may be the very scene being trained on.
_RUN_OUTPUTS = _RUN_FILES + ("metrics.json", "metrics.md", "renders", "export")


def _remove_run(run_dir, names=_RUN_OUTPUTS):
    for name in names:
        path = Path(run_dir) / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


def _refuse_existing_run(run_dir):
    found = [name for name in _RUN_FILES if (Path(run_dir) / name).exists()]
    if found:
        raise ValueError(f"{run_dir}: already holds a run ({', '.join(found)}); continue it with --resume, "
                         "choose a new --out, or pass --overwrite to replace it")


@contextlib.contextmanager
def _no_half_made_run(run_dir, fresh):
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
                _remove_run(run_dir, _RUN_FILES)
        raise


def _make_default_scene(name, data_dir):
    from velogauss.scenes import make_scene

    make_scene(name, data_dir)


def _eval_and_render(run_dir, model, cfg, data, lpips_weights):
    result = run_evaluation(run_dir, model, data, SPLIT_CHOICES["both"], lpips_weights)
    typer.echo(_headline(result, run_dir))
    written = run_render(run_dir / "renders", model, data, fps=8)
    typer.echo(f"renders: {run_dir / 'renders'} ({len(written)} files: sequence.mp4, sequence.gif, filmstrip.png, "
               "velocity_field.png, trajectories.png, frames/)")


# --- eval ------------------------------------------------------------------------------

@app.command("eval")
def eval_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    data: Optional[Path] = typer.Option(None, "--data", help="Scene folder [default: the one the run was trained on]."),
    lpips_weights: Optional[Path] = typer.Option(None, help=_LPIPS_HELP),
    split: str = typer.Option("both", help="interp | extrap | both."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
):
    """PSNR, SSIM and LPIPS on the interpolation/extrapolation splits (plus motion errors on synthetic
    scenes) -> RUN_DIR/metrics.json and RUN_DIR/metrics.md."""
    with user_errors():
        if split not in SPLIT_CHOICES:
            raise ValueError(f"--split: expected one of {', '.join(SPLIT_CHOICES)}, got {split!r}")
        check_writable(run_dir, "metrics.json", "metrics.md")
        model, cfg = load_run_model(run_dir, device)
        scene = load_run_scene(cfg, data or recorded_data_dir(run_dir))
        result = run_evaluation(run_dir, model, scene, SPLIT_CHOICES[split], lpips_weights)
    typer.echo(_headline(result, run_dir))


# --- render ----------------------------------------------------------------------------

@app.command("render")
def render_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output folder [default: RUN_DIR/renders]."),
    fps: float = typer.Option(8.0, help="Frames per second of the animation."),
    data: Optional[Path] = typer.Option(None, "--data", help="Scene folder [default: the one the run was trained on]."),
    labels: bool = typer.Option(True, "--labels/--no-labels", help="Label strip and time bar on each frame."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
):
    """Ground truth | prediction | absolute error over time, future marked (sequence.mp4, sequence.gif,
    PNG frames), the learned velocity field and the Gaussians' trajectories."""
    with user_errors():
        if not fps > 0:
            raise ValueError(f"--fps: expected a positive number, got {fps!r}")
        out = out or run_dir / "renders"
        check_writable(out)
        model, cfg = load_run_model(run_dir, device)
        scene = load_run_scene(cfg, data or recorded_data_dir(run_dir))
        written = run_render(out, model, scene, fps=fps, label=labels)
    typer.echo(f"wrote {len(written)} files to {out}")


# --- export ----------------------------------------------------------------------------

@app.command("export")
def export_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    time: str = typer.Option(..., "--time", "-t", help="Normalised time (t > max_time is the extrapolated future)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="PLY file [default: RUN_DIR/export/gaussians_t<time>.ply]."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
):
    """Write the Gaussians at one time as a standard 3DGS PLY file that splat viewers open."""
    from velogauss.export import check_time, export_ply

    with user_errors():
        t = check_time(time, "--time")
        out = out or run_dir / "export" / f"gaussians_t{t:.3f}.ply"
        check_writable(out.parent, out.name)
        model, _ = load_run_model(run_dir, device)
        count = export_ply(model, t, out)
    typer.echo(f"wrote {count} Gaussians at t={t:g} to {out}")


# --- bench -----------------------------------------------------------------------------

BENCHMARKS = ("raster", "motion", "accuracy", "effects", "export", "viewer", "load", "step_profile")


@app.command("bench")
def bench_command(
    which: str = typer.Argument(..., help=" | ".join(BENCHMARKS) + "."),
    out: Path = typer.Option(Path("benchmarks/RESULTS.md"), "--out", "-o", help="Results file (its section is replaced)."),
    device: str = typer.Option("cpu", help="Torch device to benchmark on."),
):
    """Run a benchmark (velogauss.bench.raster, .motion, .accuracy, .effects, .export, .load or .step_profile) and record it in RESULTS.md."""
    with user_errors():
        if which not in BENCHMARKS:
            raise ValueError(f"WHICH: expected one of {', '.join(BENCHMARKS)}, got {which!r}")
        module = importlib.import_module(f"velogauss.bench.{which}")
        # The results file is each benchmark's first parameter (named out_path or out).
        module.run(str(out), device=device)
    typer.echo(f"results: {out}")


# --- sweep and view (velogauss/sweep, velogauss/view) ----------------------------------

app.command("sweep")(sweep_command)
app.command("view")(view_command)


# --- walkthrough -----------------------------------------------------------------------

@app.command("walkthrough")
def walkthrough_command(
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (docs refreshes the committed copy)."),
):
    """Write the equation-by-equation walkthrough, OUT/walkthrough.md and OUT/figures/, by running the
    NumPy reference (velogauss.walkthrough)."""
    from velogauss.walkthrough import write_walkthrough

    with user_errors():
        page = write_walkthrough(out)
    typer.echo(f"wrote {page}")


# --- helpers shared by the commands ----------------------------------------------------

def train_flags(effects=None, ablation=None, iterations=None, max_time=None, half_res=None, background=None,
                device=None, threads=None):
    """The config values the `train` flags given stand for: {"section.key": (flag, value)}
    (flags left at None are not given). Raises ValueError naming `--background` when malformed.
    """
    pairs = {
        "model.effects": ("--effects", None if effects is None else [e.strip() for e in effects.split(",")]),
        "model.ablation": ("--ablation", ablation),
        "train.iterations": ("--iterations", iterations),
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


def default_run_dir(scene_name, now=None):
    """`runs/<scene>-<YYYYmmdd-HHMMSS>` (local time)."""
    stamp = (now or datetime.datetime.now()).strftime("%Y%m%d-%H%M%S")
    return Path("runs") / f"{scene_name}-{stamp}"


def build_config(path, overrides, flags=None):
    """The training config: defaults, then the TOML file `path` (if any), then `overrides`
    (["section.key=value"]), then the train `flags` (as `train_flags` returns them)."""
    if path is not None:
        _existing_file(path, "config file")
    return load_config(path, overrides, flags)


def with_data_dir(cfg, data_dir):
    """`cfg` with the scene folder recorded (absolute), so `eval` and `render` find it again."""
    import dataclasses

    return dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, dir=str(Path(data_dir).resolve())))


def recorded_data_dir(run_dir):
    """The scene folder a run was trained on, from `RUN_DIR/config.toml`."""
    cfg = load_config(_existing_file(Path(run_dir) / "config.toml", "run config"))
    if not cfg.data.dir:
        raise ValueError(f"{Path(run_dir) / 'config.toml'}: data.dir: empty; pass the scene folder with --data")
    return Path(cfg.data.dir)


def load_run_model(run_dir, device=None):
    """`(model, cfg)` of a trained run, without gradients; FileNotFoundError naming the missing
    folder or checkpoint, ValueError naming `--device` when this machine lacks it."""
    run_dir = Path(run_dir)
    if device is not None:
        check_device(device)
    if not run_dir.is_dir():
        raise FileNotFoundError(2, "run folder not found", str(run_dir))
    _existing_file(run_dir / "checkpoints" / "latest.pt", "no checkpoint in the run folder (train it first)")
    from velogauss.threads import apply_threads
    from velogauss.train.checkpoint import load_model

    model, cfg = load_model(run_dir, device or _default_device())
    apply_threads(cfg.train.threads)
    return model, cfg


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


def _default_device():
    import torch

    return "cuda" if torch.cuda.is_available() else "cpu"


def load_run_scene(cfg, data_dir):
    """The run's scene, loaded with the run's observed window, resolution and background; DataError
    for bad data or images smaller than the SSIM window."""
    from velogauss.data import check_trainable_size, load_scene

    scene = load_scene(data_dir, max_time=cfg.data.max_time, half_res=cfg.data.half_res,
                       background=cfg.data.background)
    check_trainable_size(scene)
    return scene


def run_evaluation(run_dir, model, scene, splits, lpips_weights):
    """Evaluate, write `run_dir/metrics.json` and `run_dir/metrics.md` atomically; return the result."""
    from velogauss.evaluate import evaluate_model, metrics_markdown
    from velogauss.io_utils import write_json, write_text
    from velogauss.scenes import load_ground_truth

    ground_truth = load_ground_truth(scene.root) if scene.metadata and "scene" in scene.metadata else None
    result = {"run": str(run_dir), "data": str(scene.root),
              **evaluate_model(model, scene, splits, lpips_weights, ground_truth, progress=True)}
    write_json(Path(run_dir) / "metrics.json", result)
    write_text(Path(run_dir) / "metrics.md", metrics_markdown(result, title=f"Metrics of {Path(run_dir).name}"))
    return result


def run_render(out_dir, model, scene, fps=8.0, label=True):
    """Write the pictures of `velogauss.visualize.render_run`; return their paths."""
    from velogauss.scenes import load_ground_truth
    from velogauss.visualize import render_run

    ground_truth = load_ground_truth(scene.root) if scene.metadata and "scene" in scene.metadata else None
    return render_run(model, scene, out_dir, fps=fps, ground_truth=ground_truth, label=label, progress=True)


def _headline(result, run_dir):
    from velogauss.evaluate import summary_markdown

    return f"\n{summary_markdown(result)}\nmetrics: {Path(run_dir) / 'metrics.md'} and metrics.json"


def _existing_file(path, what):
    if not Path(path).is_file():
        raise FileNotFoundError(2, f"{what} not found", str(path))
    return Path(path)


if __name__ == "__main__":
    app()
