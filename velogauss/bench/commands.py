"""`velogauss bench NAME`: one command per benchmark (registered in velogauss/cli.py).

Each command imports its benchmark when it runs, so the other commands (and `--help`) start
without torch. The defaults that a benchmark module owns (its workloads, sizes, rounds) are
passed as None and resolved there. Lists are comma-separated (`--workloads W1,W2`).
"""

from pathlib import Path
from typing import List, Optional

import typer

from velogauss.errors import user_errors

bench_app = typer.Typer(
    help="Time the fast path and write the results into benchmarks/RESULTS.md (each benchmark replaces "
         "its own section); `fidelity` runs the motion fidelity study of benchmarks/FIDELITY.md, `family` the "
         "study of the random scene family.",
    no_args_is_help=True,
)

_RESULTS = Path("benchmarks/RESULTS.md")
_OUT_HELP = "Results file (its section is replaced)."
_DEVICE_HELP = "Torch device to benchmark on."
_THREADS_HELP = "Torch CPU threads (0: torch's default)."
_QUICK_HELP = "Smoke test: a tiny configuration that runs in seconds (not for RESULTS.md)."
# The options most benchmarks share, declared once (typer reads each as a default).
_OUT = typer.Option(_RESULTS, "--out", "-o", help=_OUT_HELP)
_QUICK = typer.Option(False, "--quick", help=_QUICK_HELP)
_DEVICE = typer.Option("cpu", help=_DEVICE_HELP)
_CPU_ONLY = typer.Option("cpu", help="Torch device (the CPU only).")


def _names(text, what):
    """The comma-separated names of `text`; ValueError naming `what` when there are none."""
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    if not names:
        raise ValueError(f"{what}: expected comma-separated names, got {text!r}")
    return names


def _whole_numbers(text, what):
    """The comma-separated whole numbers of `text`; ValueError naming `what` otherwise."""
    names = _names(text, what)
    if not all(name.isdigit() for name in names):
        raise ValueError(f"{what}: expected comma-separated whole numbers, got {text!r}")
    return [int(name) for name in names]


def _done(out):
    typer.echo(f"results: {out}")


def _record(run, out, *args, **kwargs):
    """Call a benchmark's `run(out, *args, **kwargs)`, bad input as one error line, then say where."""
    with user_errors():
        run(str(out), *args, **kwargs)
    _done(out)


@bench_app.command("raster")
def raster_command(
    workloads: Optional[str] = typer.Option(None, help="Some of W1, W2, W3, W4, quick (default: W1,W2,W3,W4)."),
    methods: Optional[str] = typer.Option(
        None, help="Some of numba, torch, gsplat, autograd, dense, reference (default: all)."),
    quick: bool = typer.Option(False, "--quick", help="Smoke test: the 12 x 12, 24-Gaussian workload, one timed pass."),
    in_process: bool = typer.Option(False, "--in-process",
                                    help="Measure in this process, not one fresh process per measurement."),
    repeats: Optional[int] = typer.Option(None, help="Timed passes per process (default: by method and workload)."),
    rounds: int = typer.Option(3, help="Rounds of one process per method."),
    memory_limit_gib: float = typer.Option(24.0, help="Skip the dense renderer where its tensors need more."),
    device: str = _DEVICE,
    threads: int = typer.Option(0, help=_THREADS_HELP),
    out: Path = _OUT,
):
    """Rasterizer: forward + backward time and peak memory of every renderer (velogauss.bench.raster)."""
    from velogauss.bench import raster

    with user_errors():
        chosen = ("quick",) if quick else (raster.DEFAULT_WORKLOADS if workloads is None
                                           else _names(workloads, "--workloads"))
        raster.run(str(out), chosen, raster.METHODS if methods is None else _names(methods, "--methods"),
                   repeats or (1 if quick else None), memory_limit_gib, device, threads=threads,
                   in_process=in_process, rounds=1 if quick else rounds)
    _done(out)


@bench_app.command("motion")
def motion_command(
    repeats: Optional[int] = typer.Option(None, help="Timed passes per case (default: 5; 1 with --quick)."),
    quick: bool = _QUICK,
    in_process: bool = typer.Option(False, "--in-process",
                                    help="Measure in this process, not one fresh process per case."),
    device: str = _DEVICE,
    threads: int = typer.Option(0, help=_THREADS_HELP),
    out: Path = _OUT,
):
    """Motion and physics residuals: time and peak memory of the trajectory and of the residuals
    against a reverse-mode baseline (velogauss.bench.motion)."""
    from velogauss.bench import motion

    _record(motion.run, out, device, repeats or (1 if quick else 5), threads or None, quick=quick,
            in_process=in_process)


@bench_app.command("accuracy")
def accuracy_command(
    quick: bool = _QUICK,
    device: str = _DEVICE,
    threads: int = typer.Option(0, help=_THREADS_HELP),
    out: Path = _OUT,
):
    """Integrators: what accuracy costs in time, Euler, RK2 and RK4 (velogauss.bench.accuracy)."""
    from velogauss.bench import accuracy

    _record(accuracy.run, out, device, quick=quick, threads=threads or None)


@bench_app.command("effects")
def effects_command(
    points: int = typer.Option(5000, help="Gaussians on the scene's surfaces."),
    repeats: int = typer.Option(5, help="Timed passes per configuration."),
    threads: int = typer.Option(1, help="Torch CPU threads."),
    quick: bool = _QUICK,
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Effect profiles: the motion cost of one training iteration under each (velogauss.bench.effects)."""
    from velogauss.bench import effects

    _record(effects.run, out, device, n_points=points, repeats=repeats, threads=threads, quick=quick)


@bench_app.command("export")
def export_command(
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Export: peak memory of `velogauss export` against the time exported (velogauss.bench.export)."""
    from velogauss.bench import export

    _record(export.run, out, device)


@bench_app.command("viewer")
def viewer_command(
    points: int = typer.Option(10_000, help="Gaussians of the model."),
    size: int = typer.Option(256, help="Frame width and height in pixels."),
    threads: int = typer.Option(0, help="0: velogauss's default, as `velogauss view`."),
    quick: bool = _QUICK,
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Viewer: frames per second of `velogauss view` on the CPU (velogauss.bench.viewer)."""
    from velogauss.bench import viewer

    _record(viewer.run, out, device, n_points=points, size=size, threads=threads, quick=quick)


@bench_app.command("load")
def load_command(
    settings: Optional[str] = typer.Option(
        None, help="Some of velogauss, torch-default, passive, one-thread (default: velogauss,torch-default)."),
    workloads: Optional[str] = typer.Option(None, help="Some of train, numba, torch (default: all)."),
    seconds: Optional[float] = typer.Option(None, help="Wall time of each measurement (default: 8; 0.2 with --quick)."),
    quick: bool = typer.Option(False, "--quick",
                               help="Smoke test: a 16 px scene, the 12 x 12 render, short measurements."),
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Contention: a training iteration and a render, idle and with the cores shared (velogauss.bench.load)."""
    from velogauss.bench import load

    with user_errors():
        load.run(str(out), device,
                 settings=load.DEFAULT_SETTINGS if settings is None else _names(settings, "--settings"),
                 workloads=load.WORKLOADS if workloads is None else _names(workloads, "--workloads"),
                 seconds=seconds, quick=quick)
    _done(out)


@bench_app.command("step_profile")
def step_profile_command(
    iterations: Optional[int] = typer.Option(
        None, help="Profiled iterations (default: 40; 3 with --quick; 3 per configuration with --sizes)."),
    sizes: Optional[str] = typer.Option(
        None, metavar="PX,...", help="Profile at real resolution instead: image sizes, e.g. 400,800 (with --gaussians)."),
    gaussians: Optional[str] = typer.Option(
        None, metavar="N,...", help="The real-resolution grid's initial Gaussians, e.g. 20000,200000 (with --sizes)."),
    quick: bool = _QUICK,
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Training step profile: where an iteration's time goes, by cProfile (velogauss.bench.step_profile)."""
    from velogauss.bench import step_profile

    with user_errors():
        step_profile.run(str(out), device, iterations=iterations, quick=quick,
                         sizes=None if sizes is None else _whole_numbers(sizes, "--sizes"),
                         gaussians=None if gaussians is None else _whole_numbers(gaussians, "--gaussians"))
    _done(out)


@bench_app.command("gpu_step")
def gpu_step_command(
    size: Optional[int] = typer.Option(None, help="Image size in px (default: 800; 24 with --quick)."),
    gaussians: Optional[int] = typer.Option(None, help="Initial Gaussians (default: 100000; 200 with --quick)."),
    iterations: Optional[int] = typer.Option(None, help="Timed steps of each kind (default: 10; 2 with --quick)."),
    quick: bool = _QUICK,
    device: str = typer.Option("cuda", help="Torch device (gsplat's static step needs CUDA)."),
    out: Path = _OUT,
):
    """The dynamic training step against gsplat's static 3DGS step at the same size
    (velogauss.bench.gpu_step)."""
    from velogauss.bench import gpu_step

    _record(gpu_step.run, out, device, size=size, gaussians=gaussians, iterations=iterations, quick=quick)


@bench_app.command("step_ratio")
def step_ratio_command(
    before: str = typer.Option(..., "--before", metavar="REVISION", help="Git revision of the 'before' tree."),
    rounds: Optional[int] = typer.Option(None, help="Alternating rounds (default: 7; 2 with --quick)."),
    iterations: Optional[int] = typer.Option(None, help="Iterations per side and round (default: 20; 2 with --quick)."),
    gaussians: Optional[int] = typer.Option(None, min=1, help="Initial Gaussians (default: the scene's 2,000)."),
    quick: bool = _QUICK,
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Training step before / after a change: the time ratio of two source trees, interleaved, and
    whether they train the same numbers (velogauss.bench.step_ratio; needs git)."""
    from velogauss.bench import step_ratio

    _record(step_ratio.run, out, device=device, revision=before, rounds=rounds, iterations=iterations,
            quick=quick, gaussians=gaussians)


@bench_app.command("library")
def library_command(
    before: Optional[str] = typer.Option(None, "--before", metavar="REVISION",
                                         help="Also time the tree at this git revision, interleaved."),
    rounds: Optional[int] = typer.Option(None, help="Alternating rounds (default: 5; 1 with --quick)."),
    seconds: Optional[float] = typer.Option(None, help="Wall time of each measurement (default: 4; 0.2 with --quick)."),
    quick: bool = _QUICK,
    device: str = _CPU_ONLY,
    out: Path = _OUT,
):
    """Library use under contention: a user's script rendering, idle and beside a busy torch
    process (velogauss.bench.library)."""
    from velogauss.bench import library

    _record(library.run, out, device=device, before=before, rounds=rounds, seconds=seconds, quick=quick)


FIDELITY_ACTIONS = ("run", "table", "rescore", "pareto")


@bench_app.command("fidelity")
def fidelity_command(
    action: str = typer.Argument(..., help="run (train and score) | table | rescore (from the checkpoints) | pareto."),
    scenes: str = typer.Option("toss", help="Comma-separated scenes (`all` selects every cached one)."),
    seeds: str = typer.Option("0", help="Comma-separated seeds (or `all`)."),
    levels: str = typer.Option("full", help="Comma-separated levels: fit, fit-all, opt, full (or `all`)."),
    variants: str = typer.Option("a", help="Comma-separated training variants (or `all`)."),
    set_: List[str] = typer.Option([], "--set", help="Extra config override KEY=VALUE; repeatable."),
    cache: Path = typer.Option(Path("runs/fidelity"), help="Folder of the per-run results and runs."),
    threads: int = typer.Option(1, help="Torch CPU threads."),
    plot: Path = typer.Option(Path("benchmarks/fidelity/pareto.png"), help="Where `pareto` writes its PNG."),
):
    """Motion fidelity study: where the velocity error enters and which training scheme removes it
    (velogauss.bench.fidelity, benchmarks/FIDELITY.md)."""
    from velogauss.bench import fidelity

    with user_errors():
        if action not in FIDELITY_ACTIONS:
            raise ValueError(f"ACTION: expected one of {', '.join(FIDELITY_ACTIONS)}, got {action!r}")
        fidelity.study(action, scenes=scenes, seeds=seeds, levels=levels, variants=variants, overrides=set_,
                       cache=str(cache), threads=threads, plot=str(plot))


@bench_app.command("dnerf")
def dnerf_command(
    sweep: Path = typer.Argument(..., help="The folder of `velogauss sweep benchmarks/grids/dnerf_standard.toml`."),
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown to this file."),
):
    """The D-NeRF reconstruction table of a finished sweep beside DefGS's and 4DGS's published figures (Markdown)."""
    from velogauss.bench import dnerf

    with user_errors():
        typer.echo(dnerf.table(sweep, write), nl=False)


@bench_app.command("dnerf-future")
def dnerf_future_command(
    sweep: Path = typer.Argument(..., help="The folder of `velogauss sweep benchmarks/grids/dnerf_future.toml`."),
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown to this file."),
):
    """The D-NeRF extrapolation table of a finished sweep: full, deformation-only and the frozen frame beside
    ODE-GS's published mean (Markdown)."""
    from velogauss.bench import dnerf_future

    with user_errors():
        typer.echo(dnerf_future.table(sweep, write), nl=False)


family_app = typer.Typer(
    help="The scene family's study (velogauss.bench.family): `scenes` renders seeds' scenes and their sweep "
         "grid, `table` the per-scene scores, their spread by kind of motion and the targets, `translation-only` "
         "each scene's own velocity score without spin, `budgets` and `pareto` accuracy against training time.",
    no_args_is_help=True,
)
bench_app.add_typer(family_app, name="family")
_FAMILY_OUT = typer.Option(Path("runs/family"), "--out", "-o", help="The study's folder: data/, grid.toml, runs.")


@family_app.command("scenes")
def family_scenes_command(
    seeds: str = typer.Option(..., help="tuning, report (velogauss.scenes.family's lists) or comma-separated seeds."),
    out: Path = _FAMILY_OUT,
    ablations: str = typer.Option("full,deform-only", help="Comma-separated ablations trained on every scene."),
    set_: List[str] = typer.Option([], "--set", help="Config override KEY=VALUE of every run; repeatable."),
):
    """Render each seed's scene into OUT/data/random-SEED (unless there), write OUT/grid.toml for `velogauss sweep`."""
    from velogauss.bench import family

    with user_errors():
        family.scenes(seeds, out, _names(ablations, "--ablations"), set_, echo=typer.echo)


@family_app.command("translation-only")
def family_translation_only_command(
    seeds: str = typer.Option(..., help="tuning, report (velogauss.scenes.family's lists) or comma-separated seeds."),
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown to this file."),
):
    """Each scene's own velocity error if every body moved with its true mean velocity and did not spin (Markdown)."""
    from velogauss.bench import family
    from velogauss.io_utils import write_text

    with user_errors():
        text = family.translation_only_markdown(family.translation_only(family.parse_seeds(seeds)))
        if write is not None:
            write_text(write, text)
        typer.echo(text, nl=False)


@family_app.command("table")
def family_table_command(
    out: Path = _FAMILY_OUT,
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown to this file."),
):
    """Per-scene scores of the finished runs, their spread over scenes and kinds of motion, the targets (Markdown)."""
    from velogauss.bench import family

    with user_errors():
        typer.echo(family.table(out, write), nl=False)


@family_app.command("budgets")
def family_budgets_command(
    seeds: str = typer.Option(..., help="tuning, report (velogauss.scenes.family's lists) or comma-separated seeds."),
    fractions: str = typer.Option("0.25,0.5", help="Comma-separated shares in (0, 1) of each scene's default "
                                                    "iterations, each trained beside the default."),
    out: Path = _FAMILY_OUT,
):
    """Render each seed's scene (unless there) and write OUT/grid.toml: its default run and shorter ones."""
    from velogauss.bench import family_budget

    with user_errors():
        family_budget.budgets(seeds, fractions, out, echo=typer.echo)


@family_app.command("pareto")
def family_pareto_command(
    out: Path = _FAMILY_OUT,
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write the accuracy-against-time plot here (PNG)."),
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown to this file."),
):
    """Per budget over the scenes: cost against the default run and the family's scores (Markdown)."""
    from velogauss.bench import family_budget

    with user_errors():
        typer.echo(family_budget.pareto(out, plot, write), nl=False)


@bench_app.command("futures")
def futures_command(
    runs: List[Path] = typer.Argument(..., help="Trained run folders whose scene has frames past the window."),
    write: Optional[Path] = typer.Option(None, "--write", help="Also write the Markdown here, the records as JSON "
                                                               "beside it."),
):
    """Each run's extrapolation under every future (hold, coast, integrate, fit) without retraining, and each
    policy's spread over the runs against the freeze baseline (velogauss.bench.futures; Markdown)."""
    from velogauss.bench import futures

    with user_errors():
        typer.echo(futures.run(runs, write), nl=False)
