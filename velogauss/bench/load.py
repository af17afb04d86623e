"""Contention benchmark: a training iteration and the W2 render, idle and with the cores shared.

For each thread setting, a fresh worker process times, one after the other:

* `train`: iterations (`Trainer.step` + `adapt_gaussians`) of the default training on the default
  scene (`velogauss make-scene`'s defaults), from iteration warmup + curriculum on: motion,
  ADF and the full physics loss are on, the model is the one training starts from;
* `numba`, `torch`: forward + backward of the rasterizer benchmark's W2 render (128 x 128,
  10,000 Gaussians, velogauss.bench.raster.make_scene) with that backend;

under three conditions: `idle`; `busy`, beside one CPU-bound process (a Python busy loop,
one thread); `training`, beside a second training of the same setting (this benchmark's own
`train` worker, looping until stopped). Each time is the mean over the passes of
`--seconds` of wall time after two warm-up passes, so it is the throughput a user sees.
The slowdown is the time under a condition over the idle time of the same setting: 2x is
the fair share of a 2-core machine with one competitor.

Settings (velogauss.threads): `velogauss` is the default (`--threads 0`: one torch thread,
one compositing thread per core, OMP_WAIT_POLICY=PASSIVE); `torch-default` is what ran
before (torch's and the compositing kernels' threads = the cores, libgomp's default wait
policy); `passive` is torch-default with OMP_WAIT_POLICY=PASSIVE; `one-thread` is
`--threads 1`. Workers start without the caller's OMP_*/MKL_*/NUMBA_* thread variables.

Regenerate: velogauss bench load
Smoke test: velogauss bench load --quick --out /tmp/bench.md
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from velogauss.threads import available_cores

SECTION = "## Contention"
COMMAND = "velogauss bench load"
WORKLOADS = ("train", "numba", "torch")
CONDITIONS = ("idle", "busy", "training")
# name: (OMP_WAIT_POLICY in the worker's environment or None, train.threads; None: the cores)
SETTINGS = {
    "velogauss": ("PASSIVE", 0),
    "torch-default": (None, None),
    "passive": ("PASSIVE", None),
    "one-thread": ("PASSIVE", 1),
}
DEFAULT_SETTINGS = ("velogauss", "torch-default")
# Thread variables of the caller's shell that would override the settings under test.
_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_WAIT_POLICY")
_BUSY_LOOP = "while True: pass"
_WARMUP_PASSES = 2
_MIN_PASSES = 3
_READY = "ready"
# Wall seconds per measurement: short enough that no densification (every 100 iterations) falls inside.
DEFAULT_SECONDS = 8.0
QUICK_SECONDS = 0.2


def worker_env(setting):
    """The environment of a worker or competitor of `setting`: the caller's, without its thread
    variables, with the setting's OMP_WAIT_POLICY."""
    policy, _ = SETTINGS[setting]
    env = {k: v for k, v in os.environ.items() if k not in _THREAD_VARS}
    if policy is not None:
        env["OMP_WAIT_POLICY"] = policy
    return env


def setting_threads(setting):
    """train.threads of `setting` (0: velogauss's automatic choice)."""
    threads = SETTINGS[setting][1]
    return available_cores() if threads is None else threads


# --- the worker (a fresh process per setting and condition) ------------------------------

# The motion form the default's backtest chooses on the default scene (the main job's
# motion_form.json: rigid, one body), set so that the benchmarks time the run's iterations
# without first training the probe (velogauss.train.backtest).
DEFAULT_FORM = ("model.patterns=rigid", "model.mixing_init=uniform",
                'model.effects=["translation", "rotation", "gravity", "static"]')


def training_loop(scene_dir, threads, device="cpu"):
    """The `Trainer` of the default config on `scene_dir` (velogauss.train.loop.prepare) on
    `device`, with the form its backtest chooses there (DEFAULT_FORM), and the first iteration
    the benchmarks time: warmup + curriculum, with motion, ADF and the full physics loss on."""
    from velogauss.config import SCHEDULE_ITERATIONS, load_config
    from velogauss.data import load_scene
    from velogauss.train.loop import prepare

    # The default scene's budget: the quick scene's 2 training cameras per time would stretch
    # "auto" to 4,500 iterations (spec/density.md), and another schedule than the one timed before.
    cfg = load_config(overrides=[f"train.threads={threads}", f"train.device={device}",
                                 f"train.iterations={SCHEDULE_ITERATIONS}", *DEFAULT_FORM])
    data = load_scene(scene_dir, max_time=cfg.data.max_time, background=cfg.data.background)
    loop, _ = prepare(cfg, data, tempfile.mkdtemp(prefix="velogauss-load-"))
    return loop, loop.cfg.train.warmup + loop.cfg.train.curriculum


def training_pass(scene_dir, threads):
    """A function running one training iteration of the default config on `scene_dir`, and
    the number of Gaussians it trains."""
    loop, first = training_loop(scene_dir, threads)
    return next_iterations(loop, first), len(loop.model.gaussians)


def next_iterations(loop, first):
    """A function running the `Trainer` `loop`'s next iteration from `first` on, each call one:
    its step, then its density control."""
    counter = {"it": first}

    def one_pass():
        loop.step(counter["it"])
        counter["it"] += 1
        loop.adapt_gaussians(counter["it"])

    return one_pass


def _render_pass(backend, quick):
    """A function running one forward + backward W2 render with `backend`."""
    import torch

    from velogauss.bench.raster import WORKLOADS as RASTER_WORKLOADS
    from velogauss.bench.raster import make_scene
    from velogauss_fast.raster import rasterize

    scene = make_scene(RASTER_WORKLOADS["quick" if quick else "W2"])
    leaves = [scene[k].requires_grad_() for k in ("means", "quats", "scales", "opacities", "colors")]
    g = torch.Generator().manual_seed(1)
    v_image = torch.rand(scene["height"], scene["width"], 3, generator=g)

    def one_pass():
        for t in leaves:
            t.grad = None
        image, _, _ = rasterize(**scene, backend=backend)
        (image * v_image).sum().backward()

    return one_pass, len(leaves[0])


def _timed(one_pass, seconds):
    """Mean wall seconds per pass over `seconds` (at least _MIN_PASSES), after the warm-up."""
    for _ in range(_WARMUP_PASSES):
        one_pass()
    count, t0 = 0, time.perf_counter()
    while count < _MIN_PASSES or time.perf_counter() - t0 < seconds:
        one_pass()
        count += 1
    return (time.perf_counter() - t0) / count, count


def _worker(setting, workloads, seconds, scene_dir, quick):
    """Time `workloads` in this process under `setting`; returns {workload: result}."""
    from velogauss.threads import apply_threads

    threads = setting_threads(setting)
    results = {}
    for workload in workloads:
        if workload == "train":
            one_pass, n = training_pass(scene_dir, threads)
        else:
            apply_threads(threads)
            one_pass, n = _render_pass(workload, quick)
        mean_s, count = _timed(one_pass, seconds)
        results[workload] = {"mean_s": mean_s, "passes": count, "gaussians": n}
    import torch

    from velogauss_fast.backends import numba_backend

    return {"results": results, "torch_threads": torch.get_num_threads(),
            "composite_threads": numba_backend.get_num_threads(),
            "wait_policy": os.environ.get("OMP_WAIT_POLICY", "libgomp default")}


def _competitor_training(setting, scene_dir):
    """Train forever (the `training` condition's competitor); says `ready` after its warm-up."""
    one_pass, _ = training_pass(scene_dir, setting_threads(setting))
    for _ in range(_WARMUP_PASSES):
        one_pass()
    print(_READY, flush=True)
    while True:
        one_pass()


# --- the driver ------------------------------------------------------------------------

def _start_competitor(condition, setting, scene_dir):
    """Start the competitor of `condition` (None when idle) and return it once it runs."""
    if condition == "idle":
        return None
    if condition == "busy":
        return subprocess.Popen([sys.executable, "-c", _BUSY_LOOP], env=worker_env(setting))
    arguments = {"setting": setting, "scene_dir": str(scene_dir)}
    proc = subprocess.Popen([sys.executable, "-m", "velogauss.bench.load", "competitor", json.dumps(arguments)],
                            env=worker_env(setting), stdout=subprocess.PIPE, text=True)
    if proc.stdout.readline().strip() != _READY:
        proc.kill()
        raise RuntimeError(f"the competing training ({setting}) did not start: exit code {proc.wait()}")
    return proc


def _stop(proc):
    if proc is not None:
        proc.kill()
        proc.wait()


def _measure(setting, condition, workloads, seconds, scene_dir, quick):
    """One worker process of `setting` timing `workloads` under `condition`."""
    competitor = _start_competitor(condition, setting, scene_dir)
    try:
        arguments = {"setting": setting, "workloads": list(workloads), "seconds": seconds, "scene_dir": str(scene_dir),
                     "quick": quick}
        proc = subprocess.run([sys.executable, "-m", "velogauss.bench.load", "worker", json.dumps(arguments)],
                              capture_output=True, text=True, env=worker_env(setting))
    finally:
        _stop(competitor)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        raise RuntimeError(f"worker {setting}/{condition} failed: {tail}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def make_default_scene(out_dir, quick=False, n_points=None, resolution=None):
    """The default synthetic scene (make-scene's defaults; 16 px, 4 views, 5 times when quick),
    its point cloud `n_points` large when given; at `resolution` px when given, with 5 views
    (3 trained) at 6 times and one ray per pixel, so that an 800 px scene renders in seconds."""
    from velogauss.scenes import DEFAULT_SCENE, make_scene

    options = dict(resolution=16, n_views=4, n_times=5, n_points=200) if quick else {}
    if resolution:
        options.update(resolution=resolution, n_views=5, n_times=6, supersample=1)
    if n_points:
        options["n_points"] = n_points
    return make_scene(DEFAULT_SCENE, out_dir, **options)


def run(out_path="benchmarks/RESULTS.md", device="cpu", settings=DEFAULT_SETTINGS, workloads=WORKLOADS,
        seconds=None, quick=False, echo=print):
    """Measure every setting x condition x workload and write the "## Contention" section.

    seconds: wall time of each measurement (default: DEFAULT_SECONDS, QUICK_SECONDS when
    quick). Returns {(setting, condition): worker result}. CPU only (the contention is the CPU's).
    """
    default_seconds = QUICK_SECONDS if quick else DEFAULT_SECONDS
    seconds = default_seconds if seconds is None else seconds
    if device != "cpu":
        raise ValueError(f"--device: the contention benchmark measures CPU threads; expected cpu, got {device!r}")
    for s in settings:
        if s not in SETTINGS:
            raise ValueError(f"settings: unknown setting {s!r}; expected some of {', '.join(SETTINGS)}")
    for w in workloads:
        if w not in WORKLOADS:
            raise ValueError(f"workloads: unknown workload {w!r}; expected some of {', '.join(WORKLOADS)}")
    if not seconds > 0:
        raise ValueError(f"seconds: expected a positive number, got {seconds!r}")
    measured = {}
    with tempfile.TemporaryDirectory(prefix="velogauss-load-scene-") as tmp:
        scene_dir = make_default_scene(Path(tmp) / "scene", quick)
        for setting in settings:
            for condition in CONDITIONS:
                measured[setting, condition] = r = _measure(setting, condition, workloads, seconds, scene_dir, quick)
                echo(json.dumps({"setting": setting, "condition": condition} | r))
    from velogauss.bench.harness import machine, regenerate_command, write_section

    options = []
    if tuple(settings) != DEFAULT_SETTINGS:
        options.append("--settings " + ",".join(settings))
    if tuple(workloads) != WORKLOADS:
        options.append("--workloads " + ",".join(workloads))
    if seconds != default_seconds:
        options.append(f"--seconds {seconds:g}")
    text = "\n\n".join([
        SECTION,
        "Time per pass under contention (velogauss.bench.load): `train` is one training iteration of the default "
        "config on the default scene (motion, ADF and full physics loss on, the model training starts from), "
        "`numba` and `torch` one forward + backward W2 render (128 x 128, 10,000 Gaussians) with that backend. "
        "Conditions: idle; beside one CPU-bound process (a Python busy loop); beside a second training of the "
        "same setting. Each time is the mean over the passes of a fixed wall time, in a fresh process per "
        "setting and condition; slowdown = time / idle time of the same setting (2x is the fair share of 2 "
        "cores with one competitor). Settings: `velogauss` = the default (one torch thread, one compositing "
        "thread per core, OMP_WAIT_POLICY=PASSIVE); `torch-default` = torch's and the kernels' threads = "
        "cores, libgomp's default wait policy (what ran before); `passive` = torch-default with "
        "OMP_WAIT_POLICY=PASSIVE; `one-thread` = `--threads 1`.",
        f"Machine: {machine()}; {available_cores()} cores available to the process.",
        f"Regenerate: `{regenerate_command(COMMAND, *options, quick=quick)}`",
        _table(measured, settings, workloads),
    ])
    write_section(out_path, SECTION, text)
    return measured


def _table(measured, settings, workloads):
    lines = ["| setting | workload | idle (ms) | beside a busy process (ms) | beside a 2nd training (ms) "
             "| slowdown busy | slowdown training | threads (torch / compositing) |",
             "|---|---|---|---|---|---|---|---|"]
    for s in settings:
        idle = measured[s, "idle"]
        threads = f"{idle['torch_threads']} / {idle['composite_threads']}"
        for w in workloads:
            t = {c: 1e3 * measured[s, c]["results"][w]["mean_s"] for c in CONDITIONS}
            lines.append(f"| {s} | {w} | {t['idle']:.2f} | {t['busy']:.2f} | {t['training']:.2f} "
                         f"| {t['busy'] / t['idle']:.2f}x | {t['training'] / t['idle']:.2f}x | {threads} |")
    return "\n".join(lines)


if __name__ == "__main__":  # `_measure`'s worker or `_start_competitor`'s training: role, then arguments as JSON
    role, arguments = sys.argv[1], json.loads(sys.argv[2])
    if role == "competitor":
        _competitor_training(**arguments)
    else:
        print(json.dumps(_worker(**arguments)))
