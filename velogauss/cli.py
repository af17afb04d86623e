"""The `velogauss` command: make a synthetic scene, train, evaluate, render, export, view, sweep,
benchmark, diagnose.

Each command reads and checks its flags, then calls the layer that does the job: the run
folder (`velogauss.run`: config, checkpoint, metrics, renders), `velogauss.sweep`,
`velogauss.view`, `velogauss.bench` (`velogauss bench NAME`), `velogauss.diagnose`
(`velogauss diagnose NAME`). Outputs are checked for writability before any work starts.

Bad input prints one line `error: <what is wrong, naming the file, field or value>` and exits
with code 2 (`velogauss.errors`). Ctrl-C during training prints where the checkpoint is and
exits with code 130.

Threads (velogauss.threads): one torch thread, one compositing thread per available core and
OpenMP's passive wait policy, unless `--threads N` (config `train.threads`) or the
environment (OMP_WAIT_POLICY, OMP_NUM_THREADS) says otherwise. `main`, the console script,
sets the wait policy before any command loads torch.
"""

from pathlib import Path
from typing import List, Optional

import typer

from velogauss.bench.commands import bench_app
from velogauss.config import EFFECTS, Ablation, describe
from velogauss.diagnose.commands import diagnose_app
from velogauss.errors import user_errors
from velogauss.io_utils import check_writable
from velogauss.run import (build_config, check_device, default_run_dir, existing_file, headline, load_run_model,
                           load_run_scene, motion_form_line, no_half_made_run, recorded_data_dir, refuse_existing_run,
                           remove_run, run_evaluation, run_render, train_flags, with_data_dir)
from velogauss.sweep.command import sweep_command
from velogauss.threads import prepare_environment
from velogauss.view.command import view_command

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

EXIT_INTERRUPTED = 130  # the shell's code for a process ended by SIGINT
SPLIT_CHOICES = {"interp": ("interpolation",), "extrap": ("extrapolation",), "both": ("interpolation", "extrapolation")}

_CONFIG_HELP = "TOML config file; its values override the defaults."
_SET_HELP = ("Override one config value, KEY=VALUE (e.g. train.iterations=300); repeatable; wins over --config; "
             "`velogauss config` lists the keys.")
_DEVICE_HELP = "Torch device: cpu, cuda, cuda:1 ... (default: the run's config)."
_LPIPS_HELP = ("Folder with the LPIPS weights alex.npz and vgg.npz (default: $VELOGAUSS_LPIPS_DIR, "
               "then ../shared/data/lpips beside the checkout, then the standard download).")


def main(args=None, prog_name=None):
    """The `velogauss` console script (and `python -m velogauss`): `args` (default: sys.argv[1:])."""
    prepare_environment()  # libgomp reads its wait policy once, when torch loads it
    app(args, prog_name=prog_name)


# --- make-scene ------------------------------------------------------------------------

@app.command("make-scene")
def make_scene_command(
    name: Optional[str] = typer.Argument(None, help="Scene name (see --list)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output folder (default: data/NAME, data/random-SEED)."),
    resolution: Optional[int] = typer.Option(None, help="Image width and height in pixels (default: 128)."),
    views: Optional[int] = typer.Option(None, help="Cameras on the ring, 2 of them held out (default: 8)."),
    times: Optional[int] = typer.Option(None, help="Number of time steps in [0, 1] (default: 21)."),
    seed: Optional[int] = typer.Option(None, help="Seed of the camera placement and point cloud (default: 0)."),
    monocular: Optional[bool] = typer.Option(None, "--monocular", help="One train camera per time step (D-NeRF style)."),
    random_seed: Optional[int] = typer.Option(
        None, "--random", metavar="SEED", help="Instead of NAME, draw scene SEED of the random family "
                                               "(velogauss/scenes/family.py): size, cameras and frames are drawn too."),
    list_scenes: bool = typer.Option(False, "--list", help="List the scenes and their physical effects, then exit."),
    scene_format: Optional[str] = typer.Option(
        None, "--format", help="Layout written: dnerf (transforms_{train,val,test}.json), nerfstudio "
                               "(transforms.json with per-frame intrinsics and split lists) or panoptic "
                               "(Dynamic3DGaussians' train_meta.json, test_meta.json, ims/, seg/, "
                               "init_pt_cld.npz). Default: dnerf."),
):
    """Render a synthetic physics scene to disk in the D-NeRF or nerfstudio layout (with ground truth in
    scene.json)."""
    from velogauss.scenes import DEFAULT_SCENE, SCENES, make_random_scene, make_scene, scene_listing

    if list_scenes:
        typer.echo(scene_listing(SCENES, DEFAULT_SCENE))
        return
    with user_errors():
        if (name is None) == (random_seed is None):
            raise ValueError(f"NAME: give one scene name or --random SEED; scenes: {', '.join(SCENES)} (see --list)")
        if random_seed is not None:
            given = [flag for flag, value in (("--resolution", resolution), ("--views", views), ("--times", times),
                                              ("--seed", seed), ("--monocular", monocular),
                                              ("--format", scene_format)) if value is not None]
            if given or random_seed < 0:
                raise ValueError(f"--random: expected a seed >= 0 alone (the family draws size, cameras and frames), "
                                 f"got {random_seed}" + (f" with {', '.join(given)}" if given else ""))
            name = f"random-{random_seed}"
            path = make_random_scene(random_seed, out or Path("data") / name)
        else:
            if scene_format not in (None, "dnerf", "nerfstudio", "panoptic"):
                raise ValueError(f"--format: expected dnerf, nerfstudio or panoptic, got {scene_format!r}")
            path = make_scene(name, out or Path("data") / name, resolution=128 if resolution is None else resolution,
                              n_views=8 if views is None else views, n_times=21 if times is None else times,
                              seed=seed or 0, layout="monocular" if monocular else "multiview",
                              format="dnerf" if scene_format is None else scene_format)
    typer.echo(f"wrote scene {name!r} to {path}")


# --- train -----------------------------------------------------------------------------

@app.command("train")
def train_command(
    data_dir: Optional[Path] = typer.Argument(
        None, help="Scene folder (D-NeRF/NVFi, nerfstudio or Panoptic layout, see --format). Omitted: generate the default "
                   "synthetic scene into RUN_DIR/data."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Run folder (default: runs/<scene>-<YYYYmmdd-HHMMSS>)."),
    config: Optional[Path] = typer.Option(None, "--config", "-c", help=_CONFIG_HELP),
    set_: List[str] = typer.Option([], "--set", "-s", help=_SET_HELP),
    scene: Optional[str] = typer.Option(None, help="Synthetic scene to generate when DATA_DIR is omitted (default: the default scene)."),
    effects: Optional[str] = typer.Option(
        None, help=f"Comma-separated effects the motion model may use: {','.join(EFFECTS)}; or `declared`, the "
                   "scene's own (scene.json). Default: all but oscillation, whatever the scene declares."),
    ablation: Optional[Ablation] = typer.Option(None, help="Which of the paper's components to switch off."),
    iterations: Optional[int] = typer.Option(None, help="Training iterations (default: 3000 x train.views over the views "
                                                         "an iteration finds, 9000 for monocular video); the schedule's "
                                                         "\"auto\" keys (warm-up, curriculum, physics ramp, "
                                                         "densification) scale with them."),
    resume: bool = typer.Option(
        False, "--resume", help="Continue the run in --out from its latest checkpoint; only train.iterations, "
                                 "train.device, train.threads, train.eval_every, train.checkpoint_every and data.dir "
                                 "may change."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Start a new run in an --out that already holds one, "
                                                              "replacing its config, log and checkpoint."),
    max_time: Optional[float] = typer.Option(None, help="End of the observed window; later frames are the future (default: 0.75)."),
    half_res: Optional[bool] = typer.Option(None, "--half-res/--full-res", help="Halve the image resolution."),
    data_format: Optional[str] = typer.Option(
        None, "--format", help="Layout of DATA_DIR: dnerf, nerfstudio, panoptic or auto, detected from its files (default: the "
                               "config's data.format, auto)."),
    background: Optional[str] = typer.Option(None, help="white | black | R,G,B in [0, 1]."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
    threads: Optional[int] = typer.Option(
        None, help="CPU threads for torch and the compositing kernels; 0: one torch thread and one compositing "
                   "thread per available core, which holds up best when other processes share the cores "
                   "(default: the config's train.threads, 0)."),
    evaluate: bool = typer.Option(True, "--eval/--no-eval", help="Evaluate and render after training."),
    lpips_weights: Optional[Path] = typer.Option(None, help=_LPIPS_HELP),
):
    """Train VeloGauss on a scene, then evaluate interpolation and extrapolation and render the results.

    --out must be a new folder (or one without a run) unless --resume continues the run in it
    or --overwrite replaces it."""
    from velogauss.data import LAYOUTS
    from velogauss.scenes import DEFAULT_SCENE, make_scene

    with user_errors():
        flags = train_flags(effects=effects, ablation=ablation, iterations=iterations, max_time=max_time,
                            half_res=half_res, background=background, device=device, threads=threads,
                            data_format=data_format)
        cfg_source = config
        if resume and overwrite:
            raise ValueError("--resume and --overwrite: choose one (continue the run, or replace it)")
        if resume:
            if out is None:
                raise ValueError("--resume: needs --out RUN_DIR, the run to continue")
            cfg_source = config or existing_file(out / "config.toml", "run config")
        if data_dir is not None and not data_dir.is_dir():
            raise FileNotFoundError(2, "scene folder not found", str(data_dir))
        scene_name = scene or DEFAULT_SCENE
        run_dir = out or default_run_dir(data_dir.name if data_dir is not None else scene_name)
        if not resume and not overwrite:
            refuse_existing_run(run_dir)
        if data_dir is None and scene is None and resume:
            data_dir = recorded_data_dir(run_dir)
        cfg = build_config(cfg_source, set_, flags)
        check_device(cfg.train.device, "train.device")
        check_writable(run_dir)
        if overwrite:
            remove_run(run_dir)
    with user_errors(), no_half_made_run(run_dir, fresh=not resume):
        if data_dir is None:
            data_dir = run_dir / "data"
            layout = "dnerf" if cfg.data.format == "auto" else cfg.data.format
            if not (data_dir / LAYOUTS[layout][1][0]).is_file():
                typer.echo(f"generating synthetic scene {scene_name!r} into {data_dir}")
                make_scene(scene_name, data_dir, format=layout)
        cfg = with_data_dir(cfg, data_dir)
        data = load_run_scene(cfg, data_dir)
        typer.echo(f"training on {data_dir} ({len(data.train)} train frames) -> {run_dir}")
        from velogauss.train.loop import train

        try:
            model = train(cfg, data, run_dir, resume=resume, progress=True)
        except KeyboardInterrupt as err:
            typer.secho(str(err) or "training interrupted", err=True, fg=typer.colors.YELLOW)
            raise typer.Exit(EXIT_INTERRUPTED) from None
        form = motion_form_line(run_dir)
        if form is not None:
            typer.echo(form)
    if not evaluate:
        typer.echo(f"run folder: {run_dir}")
        return
    with user_errors():
        _eval_and_render(run_dir, model, data, lpips_weights)


def _eval_and_render(run_dir, model, data, lpips_weights):
    result = run_evaluation(run_dir, model, data, SPLIT_CHOICES["both"], lpips_weights)
    typer.echo(headline(result, run_dir))
    written = run_render(run_dir / "renders", model, data, fps=8)
    typer.echo(f"renders: {run_dir / 'renders'} ({len(written)} files: sequence.mp4, sequence.gif, filmstrip.png, "
               "velocity_field.png, trajectories.png, frames/)")


# --- eval ------------------------------------------------------------------------------

@app.command("eval")
def eval_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    data: Optional[Path] = typer.Option(None, "--data", help="Scene folder (default: the one the run was trained on)."),
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
    typer.echo(headline(result, run_dir))


# --- render ----------------------------------------------------------------------------

@app.command("render")
def render_command(
    run_dir: Path = typer.Argument(..., help="Run folder written by `velogauss train`."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output folder (default: RUN_DIR/renders)."),
    fps: float = typer.Option(8.0, help="Frames per second of the animation."),
    data: Optional[Path] = typer.Option(None, "--data", help="Scene folder (default: the one the run was trained on)."),
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
    time: Optional[str] = typer.Option(
        None, "--time", "-t", help="One normalised time: one PLY (t > max_time is the extrapolated future)."),
    times: Optional[str] = typer.Option(
        None, "--times", metavar="START:STOP:STEP|t1,t2,...",
        help="A 4D sequence: one PLY per time plus index.json (each frame's time, file, observed or future) "
             "for sequence players. START:STOP:STEP includes STOP when it lands on the grid (within 1e-6 of a "
             "step), e.g. 0:1.5:0.05 gives 31 times 0 ... 1.5; or a comma list of increasing times. Times in "
             "[0, 100], at most 10000 frames."),
    out: Optional[Path] = typer.Option(
        None, "--out", "-o", help="With --time the PLY file (default: RUN_DIR/export/gaussians_t<time>.ply); with "
                                  "--times the folder (default: RUN_DIR/sequence)."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="With --times: write into an --out folder that holds files other than a previous "
                                   "sequence (files of the sequence's names are replaced, the others kept)."),
    device: Optional[str] = typer.Option(None, help=_DEVICE_HELP),
):
    """Write the Gaussians at one time (--time) or at a sequence of times (--times; one of the two) as standard
    3DGS PLY files that splat viewers open.

    A sequence is rewritten in place only over a previous sequence of this command; any other
    non-empty --out folder is refused unless --overwrite."""
    from velogauss.export import check_sequence_folder, check_time, export_ply, export_sequence, parse_times

    with user_errors():
        if (time is None) == (times is None):
            raise ValueError("--time and --times: give exactly one (--time T for one PLY, --times START:STOP:STEP "
                             "or t1,t2,... for a sequence)")
        if times is None:
            if overwrite:
                raise ValueError("--overwrite: only with --times (--time replaces its one file)")
            t = check_time(time, "--time")
            out = out or run_dir / "export" / f"gaussians_t{t:.3f}.ply"
            check_writable(out.parent, out.name)
            model, _ = load_run_model(run_dir, device)
            count = export_ply(model, t, out)
        else:
            values = parse_times(times, "--times")
            out = out or run_dir / "sequence"
            check_sequence_folder(out, len(values), overwrite, "--out")
            model, cfg = load_run_model(run_dir, device)
            index = export_sequence(model, values, out, cfg.data.max_time, run_dir, overwrite, progress=True)
    if times is None:
        typer.echo(f"wrote {count} Gaussians at t={t:g} to {out}")
        return
    future = sum(not frame["observed"] for frame in index["frames"])
    typer.echo(f"wrote {len(values)} PLYs of {index['gaussians']} Gaussians, t={values[0]:g} ... {values[-1]:g} "
               f"({len(values) - future} observed, {future} future past max_time={index['max_time']:g}), "
               f"and {out / 'index.json'}")


# --- the commands of their own packages -----------------------------------------------

@app.command("config")
def config_command(
    config: Optional[Path] = typer.Option(None, "--config", "-c", help=_CONFIG_HELP),
    set_: List[str] = typer.Option([], "--set", "-s", help=_SET_HELP),
):
    """Every config key with its value (the defaults, then --config and --set) and why it has it."""
    with user_errors():
        cfg = build_config(config, set_)
    for key, value, description in describe(cfg):
        typer.echo(f"{key} = {value!r}\n    {description}")


app.command("sweep")(sweep_command)
app.command("view")(view_command)
app.add_typer(bench_app, name="bench")
app.add_typer(diagnose_app, name="diagnose")


@app.command("walkthrough")
def walkthrough_command(
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (docs refreshes the committed copy)."),
):
    """Write the equation-by-equation walkthrough, OUT/walkthrough.md and OUT/figures/, by running the
    NumPy reference (velogauss.walkthrough)."""
    from velogauss.walkthrough import write_walkthrough  # loads the reference: only for this command

    with user_errors():
        page = write_walkthrough(out)
    typer.echo(f"wrote {page}")


if __name__ == "__main__":
    main()
