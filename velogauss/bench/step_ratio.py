"""A training iteration before and after a change of one module: the time ratio, interleaved.

The machine these benchmarks run on is shared, so two timings taken minutes apart differ by
more than most changes (the same residuals took 8.4 and 11.1 ms in consecutive rounds).
This benchmark times both implementations in one process, in alternating rounds (before,
after, before, after, ...), each round `--iterations` training iterations after two warm-up
ones, and reports the median over the rounds of the before/after ratio of the round's mean
iteration time: drift and a competitor's bursts hit both sides of a round alike.

"Before" is the module `MODULE` as it was at the git revision `--before`, loaded from `git
show` into a module of its own; its public functions are swapped in wherever the library
imported the current ones (`velogauss.model.motion`) for the "before" rounds. The iterations
are those of the step profile (`velogauss.bench.step_profile`): the default config on the
default scene from iteration warmup + curriculum on, one torch thread; `maintain` is not
run, so no densification changes the work between rounds.

Equal results: on the training's own motion parameters at the first timed iteration, in
float64, both implementations' transport residual, divergence, physics loss and its
gradients are compared on the same collocation points (largest difference and largest
value of each). A short training is not run here (velogauss train does that).

Regenerate: python -m velogauss.bench.step_ratio   (needs git and the revision)
Smoke test: python -m velogauss.bench.step_ratio --quick --out /tmp/bench.md
"""

import argparse
import statistics
import subprocess
import tempfile
import types
from pathlib import Path

import numpy as np
import torch

SECTION = "## Training step: before / after"
COMMAND = "python -m velogauss.bench.step_ratio"
MODULE = "velogauss_fast/physics/residuals.py"
# The last commit before the residuals were written out in forward mode (vmap of jvp there).
BEFORE = "08ca2b3"
ROUNDS, ITERATIONS = 7, 20
QUICK_ROUNDS, QUICK_ITERATIONS = 2, 2
_WARMUP = 2


def load_revision(path, revision):
    """The module at `path` (repository-relative) as it was at git `revision`, as a fresh module."""
    source = subprocess.run(["git", "show", f"{revision}:{path}"], capture_output=True, text=True, check=True,
                            cwd=Path(__file__).resolve().parents[2]).stdout
    module = types.ModuleType(f"before_{revision}")
    exec(compile(source, f"{revision}:{path}", "exec"), module.__dict__)
    return module


def swap(importer, functions):
    """Bind `functions` ({name: function}) in module `importer`; returns what was bound before."""
    previous = {name: getattr(importer, name) for name in functions}
    for name, fn in functions.items():
        setattr(importer, name, fn)
    return previous


def compare(before, after, params, spec, n_points, seed=0):
    """{quantity: (largest |before - after|, largest |after|)} of the `before` and `after`
    modules' `physics_residuals` (transport residual, divergence), the physics loss and its
    gradients (parameters and points), in float64 on `params` (a motion parameter dict)."""
    from velogauss_fast.losses import physics_loss

    p64 = {k: [(W.detach().double().requires_grad_(), b.detach().double().requires_grad_()) for W, b in v]
           if isinstance(v, list) else v.detach().double().requires_grad_() for k, v in params.items()}
    leaves = [t for v in p64.values() for t in (v if isinstance(v, torch.Tensor) else [u for pair in v for u in pair])]
    x = torch.tensor(np.random.default_rng(seed).uniform(-1.0, 1.0, (n_points, 3)), requires_grad=True)
    outputs = []
    for module in (before, after):
        r, div = module.physics_residuals(p64, x, 0.4, spec.config)
        loss = physics_loss(r, div, 1.0, 1.0)
        grads = torch.autograd.grad(loss, [x] + leaves, allow_unused=True)
        outputs.append({"residual": r.detach(), "divergence": div.detach(), "loss": loss.detach(),
                        "gradients": torch.cat([g.flatten() for g in grads if g is not None])})
    return {k: (float((outputs[0][k] - v).abs().max()), float(v.abs().max())) for k, v in outputs[1].items()}


def measure(revision=BEFORE, rounds=ROUNDS, iterations=ITERATIONS, quick=False):
    """{"rounds": [(before, after) mean s per iteration], "ratios", "ratio" (median before/after),
    "agreement" (`compare`), "gaussians"}."""
    from velogauss.bench.harness import timed_passes
    from velogauss.bench.load import make_default_scene, training_loop
    import velogauss.model.motion as importer
    import velogauss_fast.physics.residuals as after

    before = load_revision(MODULE, revision)
    names = [name for name in ("physics_residuals", "transport_residual", "mlp_residuals") if hasattr(importer, name)]
    functions = {"before": {n: getattr(before, n) for n in names}, "after": {n: getattr(after, n) for n in names}}
    with tempfile.TemporaryDirectory(prefix="velogauss-ratio-") as tmp:
        loop, first = training_loop(make_default_scene(Path(tmp) / "scene", quick), 1)
        counter = {"it": first}

        def one_step():
            loop.step(counter["it"])
            counter["it"] += 1

        one_step()  # the motion trains from here: its parameters have gradients
        agreement = compare(before, after, loop.model.motion.params(), loop.spec_at(counter["it"]),
                            loop.cfg.physics.n_points)
        times = []
        try:
            for _ in range(rounds):
                pair = []
                for side in ("before", "after"):
                    swap(importer, functions[side])
                    timed_passes(one_step, _WARMUP)
                    pair.append(statistics.fmean(timed_passes(one_step, iterations)))
                times.append(tuple(pair))
        finally:
            swap(importer, functions["after"])
    ratios = [b / a for b, a in times]
    return {"rounds": times, "ratios": ratios, "ratio": statistics.median(ratios), "agreement": agreement,
            "gaussians": len(loop.model.gaussians)}


def run(out_path="benchmarks/RESULTS.md", device="cpu", revision=BEFORE, rounds=None, iterations=None, quick=False):
    """Measure (`measure`) and write the "## Training step: before / after" section."""
    if device != "cpu":
        raise ValueError(f"--device: the step ratio runs on the CPU; expected cpu, got {device!r}")
    from velogauss.bench.harness import regenerate_command, write_table_section

    default_rounds, default_iterations = (QUICK_ROUNDS, QUICK_ITERATIONS) if quick else (ROUNDS, ITERATIONS)
    rounds, iterations = rounds or default_rounds, iterations or default_iterations
    torch.set_num_threads(1)
    result = measure(revision, rounds, iterations, quick)
    options = ([f"--before {revision}"] if revision != BEFORE else []) + \
              ([f"--rounds {rounds}"] if rounds != default_rounds else []) + \
              ([f"--iterations {iterations}"] if iterations != default_iterations else [])
    agreement = result["agreement"]
    lines = ["| round | before (ms per iteration) | after (ms per iteration) | before / after |", "|---:|---:|---:|---:|"]
    for k, ((b, a), ratio) in enumerate(zip(result["rounds"], result["ratios"]), 1):
        lines.append(f"| {k} | {1e3 * b:.1f} | {1e3 * a:.1f} | {ratio:.2f} |")
    write_table_section(out_path, SECTION, [
        f"A training iteration (`_Loop.step`) of the default training on the default scene ({result['gaussians']} "
        f"Gaussians; motion, ADF and full physics loss on; one torch thread) with `{MODULE}` as at "
        f"`{revision}` (before) and as now (after), in {rounds} alternating rounds of {iterations} iterations "
        f"in one process. Median before / after: **{result['ratio']:.2f}x**.",
        "Equal results (float64, the training's motion parameters at the first timed iteration, both "
        "`physics_residuals` on the same collocation points; largest difference, then largest value): "
        + ", ".join(f"{name} {diff:.1e} ({scale:.1e})" for name, (diff, scale) in agreement.items())
        + ". The divergence is a sum of grad v's diagonal terms, each much larger than it this early in "
        "training, so its difference is the rounding of those terms.",
    ], regenerate_command(COMMAND, *options, quick=quick), lines)
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=BEFORE, help=f"git revision of the 'before' module (default {BEFORE})")
    parser.add_argument("--rounds", type=int, default=None, help=f"default {ROUNDS}")
    parser.add_argument("--iterations", type=int, default=None, help=f"per side and round, default {ITERATIONS}")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke test: a 16 px scene, {QUICK_ROUNDS} rounds of {QUICK_ITERATIONS} iterations")
    parser.add_argument("--out", default="benchmarks/RESULTS.md")
    args = parser.parse_args(argv)
    run(args.out, revision=args.before, rounds=args.rounds, iterations=args.iterations, quick=args.quick)


if __name__ == "__main__":
    main()
