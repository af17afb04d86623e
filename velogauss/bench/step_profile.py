"""Where a training iteration's time goes: cProfile over iterations of the default training.

The same iterations as `velogauss bench load`'s `train` workload (the default config on the
default scene, from iteration warmup + curriculum on: motion, ADF and full physics loss on,
velogauss's default threads), run under cProfile; each row is the cumulative time of the
functions that do one part of the step, per iteration. Rows nest where their functions do
(compositing forward runs inside the render; compositing backward inside backward); the
indented rows are parts of the row above. cProfile sees only its own thread, so the side
losses (velogauss.train.aux_losses) run inline in the profiled iterations, as on one core; the
iteration times are reported unprofiled with them beside the renders (the default), unprofiled
inline, and profiled. cProfile's own cost inflates Python-heavy parts.

With `--sizes` and `--gaussians` it profiles the same step at real resolution instead
(`run_grid`): the default scene rendered at each size (5 cameras, 3 trained, 6 times, one ray
per pixel) with a point cloud of each count, so that the training starts from that many
Gaussians; a column per (size, count), in a section of its own.

Regenerate: velogauss bench step_profile
At real resolution: velogauss bench step_profile --sizes 400,800 --gaussians 20000,200000
Smoke test: velogauss bench step_profile --quick --out /tmp/bench.md
"""

import cProfile
import pstats
import tempfile
import time
from pathlib import Path

from tqdm import tqdm

SECTION = "## Training step profile"
GRID_SECTION = "## Training step profile at real resolution"
COMMAND = "velogauss bench step_profile"
ITERATIONS = 40  # below the 100 between densifications: no densification in the window
QUICK_ITERATIONS = 3
GRID_ITERATIONS = 3  # an 800 px step with 200k Gaussians takes seconds; the parts' shares settle in a few
# (label, indent, [(path suffix, function name), ...]): the functions whose cumulative time
# make up the row (summed; none of a row's functions calls another of the same row).
PARTS = [
    ("step (`Trainer.step`)", 0, [("train/loop.py", "step")]),
    ("learning rates + frame draw", 1, [("train/optim.py", "set_learning_rates"), ("train/sampling.py", "sample")]),
    ("motion parameters (`params()`)", 1, [("model/motion.py", "params")]),
    ("side losses' draws (`aux_losses.draw`)", 1, [("train/aux_losses.py", "draw")]),
    ("Gaussians at t (`moving_state_at`: the renders' and the collocation points')", 1,
     [("model/velogauss_model.py", "moving_state_at")]),
    ("render (`rasterize`)", 1, [("velogauss_fast/raster.py", "rasterize")]),
    ("preparation: VG-COV, VG-PROJ, VG-SH (numba)", 2, [("backends/numba_projection.py", "forward")]),
    ("row spans (sort, culling; numba)", 2, [("velogauss_fast/spans.py", "row_spans"),
                                             ("backends/numba_spans.py", "row_spans_numba")]),
    ("compositing forward (numba)", 2, [("backends/numba_backend.py", "forward")]),
    ("photometric loss (value and gradient, numba)", 1, [("velogauss_fast/losses.py", "photometric_loss")]),
    ("renders' backward (`loss.backward`)", 1, [("torch/_tensor.py", "backward")]),
    ("compositing backward (numba)", 2, [("backends/numba_backend.py", "backward")]),
    ("preparation backward (numba)", 2, [("backends/numba_projection.py", "backward")]),
    ("side losses (`loss_and_gradients`, inline here)", 1, [("train/aux_losses.py", "loss_and_gradients")]),
    ("collocation points' state (`collocation_near`, in the row of `moving_state_at` too)", 2,
     [("train/aux_losses.py", "collocation_near")]),
    ("physics residuals (`motion_residuals`)", 2, [("model/motion.py", "motion_residuals")]),
    ("mixing entropy (VG-LOSS-MIX, after its code pass)", 2, [("velogauss_fast/losses.py", "mixing_entropy_loss")]),
    ("side losses' backward (`autograd.grad`)", 2, [("torch/autograd/__init__.py", "grad")]),
    ("density statistics", 1, [("train/densify.py", "add")]),
    ("optimizer (Adam step)", 1, [("torch/optim/adam.py", "step")]),
    ("PSNR of the view (host sync)", 1, [("velogauss_fast/metrics.py", "psnr")]),
    ("motion, all calls: physics code z = E(γ(x0))", 1, [("motion/code.py", "physics_code")]),
    ("motion, all calls: coefficients of the stages", 1, [("motion/trajectory.py", "_stage_coefficients")]),
    ("motion, all calls: integration (rates, RK stages)", 1, [("motion/integrate.py", "integrate_schedule")]),
    ("motion, all calls: ADF", 1, [("motion/deform.py", "adf_residual")]),
    ("density control etc. (`adapt_gaussians`)", 0, [("train/loop.py", "adapt_gaussians")]),
    ("argument checks (`check_array`, `check_finite`, `check_time`)", 0,
     [("velogauss_fast/checks.py", "check_array"), ("velogauss_fast/checks.py", "check_finite"),
      ("motion/scalars.py", "check_time")]),
]


def _cumulative(stats, suffix, name):
    """(cumulative seconds, calls) of the functions `name` in files ending in `suffix`, outermost calls only."""
    total, calls = 0.0, 0
    for (path, _, func), (_, ncalls, _, cumtime, _) in stats.stats.items():
        if func == name and path.replace("\\", "/").endswith(suffix):
            total += cumtime
            calls += ncalls
    return total, calls


def measure(iterations, quick=False, resolution=None, n_points=None):
    """{"unprofiled_s", "inline_s" (side losses inline), "profiled_s" (inline too), "rows": [(label, indent,
    s per iteration, calls per iteration)], "gaussians"}: on the default scene, at `resolution` px and
    from `n_points` initial points when given (`velogauss.bench.load.make_default_scene`)."""
    from velogauss.bench.load import make_default_scene, training_loop

    with tempfile.TemporaryDirectory(prefix="velogauss-profile-") as tmp:
        scene = make_default_scene(Path(tmp) / "scene", quick, n_points=n_points, resolution=resolution)
        loop, first = training_loop(scene, 0)
        iteration = iter(range(first, first + 2 + 3 * iterations))

        def seconds_per_iteration(count):
            start = time.perf_counter()
            for _ in range(count):
                it = next(iteration)
                loop.step(it)
                loop.adapt_gaussians(it + 1)
            return (time.perf_counter() - start) / count

        seconds_per_iteration(2)
        unprofiled = seconds_per_iteration(iterations)
        # cProfile sees only its own thread: the side losses run inline from here on.
        loop.aux_worker = None
        inline = seconds_per_iteration(iterations)
        profiler = cProfile.Profile()
        profiler.enable()
        profiled = seconds_per_iteration(iterations)
        profiler.disable()
    stats = pstats.Stats(profiler)
    rows = []
    for label, indent, functions in PARTS:
        found = [_cumulative(stats, suffix, name) for suffix, name in functions]
        rows.append((label, indent, sum(s for s, _ in found) / iterations, sum(c for _, c in found) / iterations))
    return {"unprofiled_s": unprofiled, "inline_s": inline, "profiled_s": profiled, "rows": rows,
            "gaussians": len(loop.model.gaussians)}


def run(out_path="benchmarks/RESULTS.md", device="cpu", iterations=None, quick=False, sizes=None, gaussians=None):
    """Profile `iterations` training iterations (default ITERATIONS, QUICK_ITERATIONS when quick)
    and write the "## Training step profile" section; given `sizes` and `gaussians` (lists of
    image sizes in px and of initial Gaussian counts, both or neither), `run_grid` instead."""
    if device != "cpu":
        raise ValueError(f"--device: the step profile runs on the CPU; expected cpu, got {device!r}")
    if bool(sizes) != bool(gaussians):
        raise ValueError("--sizes, --gaussians: give both (the grid's image sizes and Gaussian counts) or neither")
    if sizes:
        return run_grid(out_path, sizes, gaussians, iterations or (1 if quick else GRID_ITERATIONS), quick)
    iterations = iterations or (QUICK_ITERATIONS if quick else ITERATIONS)
    from velogauss.bench.harness import regenerate_command, write_table_section

    result = measure(iterations, quick)
    step = result["rows"][0][2]
    lines = ["| part | ms per iteration | % of the step | calls per iteration |", "|---|---:|---:|---:|"]
    for label, indent, seconds, calls in result["rows"]:
        lines.append(f"| {'&nbsp;&nbsp;' * indent}{label} | {1e3 * seconds:.2f} | {100 * seconds / step:.0f}% "
                     f"| {calls:g} |")
    options = [] if iterations == (QUICK_ITERATIONS if quick else ITERATIONS) else [f"--iterations {iterations}"]
    write_table_section(out_path, SECTION, [
        f"cProfile over {iterations} iterations of the default training on the default scene "
        f"({result['gaussians']} Gaussians; motion, ADF and full physics loss on; velogauss's default threads), "
        "cumulative time per iteration of the functions doing each part. Indented rows are parts of the row "
        "above; a row's remainder is the Python and torch work between them. Iteration time: "
        f"{1e3 * result['unprofiled_s']:.1f} ms unprofiled with the side losses beside the renders (the default), "
        f"{1e3 * result['inline_s']:.1f} ms unprofiled with them inline, {1e3 * result['profiled_s']:.1f} ms "
        "profiled (inline: cProfile sees one thread; its cost inflates Python-heavy rows).",
    ], regenerate_command(COMMAND, *options, quick=quick), lines)
    return result


def run_grid(out_path, sizes, gaussians, iterations, quick=False):
    """Profile the step at each (size in px, initial Gaussians) of `sizes` x `gaussians` and write
    the "## Training step profile at real resolution" section: a column per configuration, each
    part's ms per iteration and share of the profiled step. Returns {(size, count): `measure`'s}."""
    from velogauss.bench.harness import regenerate_command, write_table_section

    for name, values in (("--sizes", sizes), ("--gaussians", gaussians)):
        if any(isinstance(v, bool) or not isinstance(v, int) or v < 16 for v in values):
            raise ValueError(f"{name}: expected whole numbers of at least 16, got {list(values)}")
    grid = [(size, count) for size in sizes for count in gaussians]
    results = {key: measure(iterations, quick, resolution=key[0], n_points=key[1])
               for key in tqdm(grid, desc="profile")}
    lines = ["| part | " + " | ".join(f"{size} px, {count:,} points" for size, count in grid) + " |",
             "|---|" + "---:|" * len(grid),
             "| iteration, unprofiled (ms) | " + " | ".join(f"{1e3 * results[k]['unprofiled_s']:.0f}" for k in grid)
             + " |",
             "| Gaussians trained | " + " | ".join(f"{results[k]['gaussians']:,}" for k in grid) + " |"]
    for index, (label, indent, _) in enumerate(PARTS):
        cells = [f"{1e3 * results[k]['rows'][index][2]:.0f} ({100 * results[k]['rows'][index][2] / results[k]['rows'][0][2]:.0f}%)"
                 for k in grid]
        lines.append(f"| {'&nbsp;&nbsp;' * indent}{label} | " + " | ".join(cells) + " |")
    options = [f"--sizes {','.join(map(str, sizes))}", f"--gaussians {','.join(map(str, gaussians))}"]
    if iterations != (1 if quick else GRID_ITERATIONS):
        options.append(f"--iterations {iterations}")
    write_table_section(out_path, GRID_SECTION, [
        "cProfile over the default training's step at real resolution: the default scene rendered at each size "
        "(5 cameras, 3 trained, 6 times, one ray per pixel) with a point cloud of each count, trained from that "
        f"many Gaussians (motion, ADF and full physics loss on; velogauss's default threads), {iterations} "
        "profiled iterations each after one to warm up. Cells: ms per iteration and the share of the profiled "
        "step; indented rows are parts of the row above, as in \"Training step profile\". The box fills a "
        "small part of the view, so these Gaussians cover fewer pixels than a real capture's.",
    ], regenerate_command(COMMAND, *options, quick=quick), lines)
    return results
