"""A training iteration before and after a change: the time ratio, interleaved, and the agreement.

The machine these benchmarks run on is shared, so two timings taken minutes apart differ by
more than most changes (one iteration measured 51 ms in one session and 77 ms in the next).
This benchmark times both versions in one run, in alternating rounds (before, after, before,
after, ...), each round `--iterations` training iterations after two warm-up ones, and
reports the median over the rounds of the before/after ratio of the round's mean iteration
time: drift and a competitor's bursts hit both sides of a round alike.

"Before" is the whole source tree at the git revision `--before` (`git archive` into a
temporary folder), "after" this checkout. Each runs in a worker process of its own, with its
own imports and its own default threads, on the same scene; the workers take turns, so only
one runs at a time. The iterations are those of the step profile (`velogauss.bench.step_profile`):
the default config on the default scene from iteration warmup + curriculum on; `adapt_gaussians` is
not run, so no densification changes the work between rounds. `--gaussians N` starts both
from a point cloud of N points instead of the scene's 2,000, the size the default training
reaches after densification (6,692 Gaussians from iteration 2,000 on), where a change can gain
less than at the start; its section is "## Training step: before / after, N Gaussians".

Equal results: both workers run the same iterations from the same start (seed, scene), so
after the last round their trainable tensors differ by the two versions' rounding only, grown
over the iterations; each tensor's largest difference is reported beside its largest value,
with the last iteration's loss of each. A change that keeps the arithmetic (as the side
losses beside the renders and the kept SSIM targets did) leaves them equal to the last bit,
and the section says so; the numba kernels of each view's preparation and of the
photometric loss (float64 inside) do not. Equal quality over a whole training is measured by training, not here (README, "Main
job"; benchmarks/RESULTS.md).

Regenerate: velogauss bench step_ratio --before REVISION   (needs git and the revision)
Smoke test: velogauss bench step_ratio --before REVISION --quick --out /tmp/bench.md
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import torch

SECTION = "## Training step: before / after"
COMMAND = "velogauss bench step_ratio"
ROUNDS, ITERATIONS = 7, 20
QUICK_ROUNDS, QUICK_ITERATIONS = 2, 2
_WARMUP = 2
_ROOT = Path(__file__).resolve().parents[2]
# What a worker runs, in its own tree: only what both versions have (velogauss.bench.load's
# training_loop). Commands on stdin, one JSON answer per line on stdout.
_WORKER = """
import json, sys, time
import torch
from velogauss.bench.load import training_loop
loop, it = training_loop(sys.argv[1], 0)
for line in sys.stdin:
    command, argument = line.split()
    if command == "run":
        start = time.perf_counter()
        for _ in range(int(argument)):
            loss, _ = loop.step(it)
            it += 1
        answer = {"seconds": time.perf_counter() - start, "loss": loss, "gaussians": len(loop.model.gaussians)}
    else:
        torch.save({k: v.detach() for k, v in loop.model.named_parameters()}, argument)
        answer = {}
    print(json.dumps(answer), flush=True)
"""


def export_revision(revision, folder):
    """The source tree at git `revision`, extracted into `folder`; returns `folder`."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "archive", revision], capture_output=True, check=True, cwd=_ROOT).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


class _Worker:
    """A training of the default config in its own process, importing velogauss from `tree`."""

    def __init__(self, tree, scene):
        env = dict(os.environ, PYTHONPATH=str(tree))
        self.process = subprocess.Popen([sys.executable, "-c", _WORKER, str(scene)], cwd=tree, env=env,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def ask(self, command, argument):
        self.process.stdin.write(f"{command} {argument}\n")
        self.process.stdin.flush()
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the worker in {self.process.args[-1]} stopped (exit {self.process.wait()})")
        return json.loads(line)

    def close(self):
        self.process.stdin.close()
        self.process.wait()


def measure(revision, rounds=ROUNDS, iterations=ITERATIONS, quick=False, gaussians=None):
    """{"rounds": [(before, after) mean s per iteration], "ratios", "ratio" (median before/after),
    "agreement" {parameter: (largest |before - after|, largest |after|)}, "losses" (before,
    after) of the last iteration, "gaussians"}. gaussians: the scene's point cloud size, None
    for the default scene's."""
    from velogauss.bench.load import make_default_scene

    with tempfile.TemporaryDirectory(prefix="velogauss-ratio-") as tmp:
        tmp = Path(tmp)
        scene = make_default_scene(tmp / "scene", quick, n_points=gaussians)
        workers = {"before": _Worker(export_revision(revision, tmp / "before"), scene), "after": _Worker(_ROOT, scene)}
        try:
            times, last = [], {}
            for _ in range(rounds):
                pair = []
                for side, worker in workers.items():
                    worker.ask("run", _WARMUP)
                    last[side] = worker.ask("run", iterations)
                    pair.append(last[side]["seconds"] / iterations)
                times.append(tuple(pair))
            for side, worker in workers.items():
                worker.ask("save", tmp / f"{side}.pt")
        finally:
            for worker in workers.values():
                worker.close()
        before, after = (torch.load(tmp / f"{side}.pt") for side in workers)
    agreement = {name: (float((before[name] - value).abs().max()), float(value.abs().max()))
                 for name, value in after.items() if name in before and before[name].shape == value.shape}
    ratios = [b / a for b, a in times]
    return {"rounds": times, "ratios": ratios, "ratio": statistics.median(ratios), "agreement": agreement,
            "losses": (last["before"]["loss"], last["after"]["loss"]), "gaussians": last["after"]["gaussians"]}


def run(out_path="benchmarks/RESULTS.md", device="cpu", *, revision, rounds=None, iterations=None, quick=False,
        gaussians=None):
    """Measure (`measure`) and write the "## Training step: before / after" section (with
    `gaussians`, a point cloud of that size: its own section)."""
    if device != "cpu":
        raise ValueError(f"--device: the step ratio runs on the CPU; expected cpu, got {device!r}")
    from velogauss.bench.harness import regenerate_command, write_table_section

    default_rounds, default_iterations = (QUICK_ROUNDS, QUICK_ITERATIONS) if quick else (ROUNDS, ITERATIONS)
    rounds, iterations = rounds or default_rounds, iterations or default_iterations
    torch.set_num_threads(1)  # the workers' default, which the section's machine line reports
    result = measure(revision, rounds, iterations, quick, gaussians)
    options = [f"--before {revision}"] + \
              ([f"--rounds {rounds}"] if rounds != default_rounds else []) + \
              ([f"--iterations {iterations}"] if iterations != default_iterations else []) + \
              ([f"--gaussians {gaussians}"] if gaussians else [])
    lines = ["| round | before (ms per iteration) | after (ms per iteration) | before / after |", "|---:|---:|---:|---:|"]
    for k, ((b, a), ratio) in enumerate(zip(result["rounds"], result["ratios"]), 1):
        lines.append(f"| {k} | {1e3 * b:.1f} | {1e3 * a:.1f} | {ratio:.2f} |")
    section = f"{SECTION}, {gaussians:,} Gaussians" if gaussians else SECTION
    write_table_section(out_path, section, [
        f"A training iteration (`Trainer.step`) of the default training on the default scene"
        f"{f' with a point cloud of {gaussians:,} points' if gaussians else ''} ({result['gaussians']} Gaussians; motion, ADF and full physics loss on; velogauss's default threads) with the source tree at "
        f"`{revision}` (before) and this one (after), each in a process of its own, in {rounds} alternating rounds "
        f"of {iterations} iterations. Median before / after: **{result['ratio']:.2f}x**.",
        _agreement_sentence(result, rounds * (iterations + _WARMUP)),
    ], regenerate_command(COMMAND, *options, quick=quick), lines)
    return result


def _agreement_sentence(result, iterations):
    """The section's sentence on equal results after `iterations` of both versions."""
    losses = f"last loss {result['losses'][0]:.6f} before, {result['losses'][1]:.6f} after"
    worst = max(result["agreement"].items(), key=lambda item: item[1][0] / max(item[1][1], 1e-30))
    if worst[1][0] == 0:
        return (f"Equal results: after the {iterations} iterations both ran from the same start, every trainable "
                f"tensor is equal to the last bit ({losses}; the reported loss is a sum taken in another order). "
                "So a whole training is the same as before, to the last digit of every result.")
    return (f"Equal results: after the {iterations} iterations both ran from the same start, the largest relative "
            f"difference of a trainable tensor is {worst[1][0] / max(worst[1][1], 1e-30):.1e} (`{worst[0]}`: "
            f"{worst[1][0]:.1e} of {worst[1][1]:.1e}); {losses}. The versions differ in rounding, which training "
            "carries on; equal quality over whole trainings is measured over seeds in \"Toward a 2x step\" below.")
