"""Where a training iteration's time goes: cProfile over iterations of the default training.

The same iterations as `velogauss bench load`'s `train` workload (the default config on the
default scene, from iteration warmup + curriculum on: motion, ADF and full physics loss on,
velogauss's default threads), run under cProfile; each row is the cumulative time of the
functions that do one part of the step, per iteration. Rows nest where their functions do
(compositing forward runs inside the render; compositing backward inside backward); the
indented rows are parts of the row above. cProfile's own cost inflates Python-heavy parts:
the profiled and the unprofiled iteration times are both reported.

Regenerate: python -m velogauss.bench.step_profile   (or: velogauss bench step_profile)
Smoke test: python -m velogauss.bench.step_profile --quick --out /tmp/bench.md
"""

import argparse
import cProfile
import pstats
import tempfile
import time
from pathlib import Path

SECTION = "## Training step profile"
COMMAND = "python -m velogauss.bench.step_profile"
ITERATIONS = 40  # below the 100 between densifications: no densification in the window
QUICK_ITERATIONS = 3
# (label, indent, [(path suffix, function name), ...]): the functions whose cumulative time
# make up the row (summed; none of a row's functions calls another of the same row).
PARTS = [
    ("step (`_Loop.step`)", 0, [("train/loop.py", "step")]),
    ("learning rates + frame draw", 1, [("train/optim.py", "set_learning_rates"), ("train/sampling.py", "sample")]),
    ("motion parameters (`params()`)", 1, [("model/motion.py", "params")]),
    ("motion: Gaussians at t (`state_at`)", 1, [("model/dynamic.py", "state_at")]),
    ("physics code z = E(γ(x0))", 2, [("motion/code.py", "physics_code")]),
    ("coefficients of the stages", 2, [("motion/trajectory.py", "_stage_coefficients")]),
    ("integration (rates, RK stages)", 2, [("motion/integrate.py", "integrate_schedule")]),
    ("ADF", 2, [("motion/deform.py", "adf_residual")]),
    ("render (`rasterize`)", 1, [("velogauss_fast/raster.py", "rasterize")]),
    ("projection (VG-PROJ)", 2, [("velogauss_fast/projection.py", "project_gaussians")]),
    ("row spans (sort, culling)", 2, [("velogauss_fast/spans.py", "row_spans")]),
    ("compositing forward (numba)", 2, [("backends/numba_backend.py", "forward")]),
    ("photometric loss", 1, [("velogauss_fast/losses.py", "photometric_loss")]),
    ("physics residuals (`motion_residuals`)", 1, [("model/motion.py", "motion_residuals")]),
    ("mixing entropy (`mixing_loss`, VG-LOSS-MIX)", 1, [("train/loop.py", "mixing_loss")]),
    ("backward (`loss.backward`)", 1, [("torch/_tensor.py", "backward")]),
    ("compositing backward (numba)", 2, [("backends/numba_backend.py", "backward")]),
    ("density statistics", 1, [("train/densify.py", "add")]),
    ("optimizer (Adam step)", 1, [("torch/optim/adam.py", "step")]),
    ("PSNR of the view (host sync)", 1, [("velogauss_fast/metrics.py", "psnr")]),
    ("density control etc. (`maintain`)", 0, [("train/loop.py", "maintain")]),
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


def measure(iterations, quick=False):
    """{"unprofiled_s", "profiled_s", "rows": [(label, indent, s per iteration, calls per iteration)], "gaussians"}."""
    from velogauss.bench.load import make_default_scene, training_pass

    with tempfile.TemporaryDirectory(prefix="velogauss-profile-") as tmp:
        scene = make_default_scene(Path(tmp) / "scene", quick)
        one_pass, n = training_pass(scene, 0)
        for _ in range(2):
            one_pass()
        t0 = time.perf_counter()
        for _ in range(iterations):
            one_pass()
        unprofiled = (time.perf_counter() - t0) / iterations
        profiler = cProfile.Profile()
        t0 = time.perf_counter()
        profiler.enable()
        for _ in range(iterations):
            one_pass()
        profiler.disable()
        profiled = (time.perf_counter() - t0) / iterations
    stats = pstats.Stats(profiler)
    rows = []
    for label, indent, functions in PARTS:
        found = [_cumulative(stats, suffix, name) for suffix, name in functions]
        rows.append((label, indent, sum(s for s, _ in found) / iterations, sum(c for _, c in found) / iterations))
    return {"unprofiled_s": unprofiled, "profiled_s": profiled, "rows": rows, "gaussians": n}


def run(out_path="benchmarks/RESULTS.md", device="cpu", iterations=None, quick=False):
    """Profile `iterations` training iterations (default ITERATIONS, QUICK_ITERATIONS when quick)
    and write the "## Training step profile" section."""
    iterations = iterations or (QUICK_ITERATIONS if quick else ITERATIONS)
    if device != "cpu":
        raise ValueError(f"--device: the step profile runs on the CPU; expected cpu, got {device!r}")
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
        f"{1e3 * result['unprofiled_s']:.1f} ms unprofiled, {1e3 * result['profiled_s']:.1f} ms profiled "
        "(cProfile's cost inflates Python-heavy rows).",
    ], regenerate_command(COMMAND, *options, quick=quick), lines)
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=None, help=f"default {ITERATIONS}")
    parser.add_argument("--quick", action="store_true", help=f"smoke test: a 16 px scene, {QUICK_ITERATIONS} iterations")
    parser.add_argument("--out", default="benchmarks/RESULTS.md")
    args = parser.parse_args(argv)
    run(args.out, iterations=args.iterations, quick=args.quick)


if __name__ == "__main__":
    main()
