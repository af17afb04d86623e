"""Library use under contention: `velogauss_fast.rasterize` from a user's own script.

A user's script imports torch first and then `velogauss_fast`, and sets no thread policy
(velogauss.threads is the command's; docs/usage.md, "Threads, from your own script"). This
benchmark runs such a script in a fresh process (`_SCRIPT`: forward + backward of the
rasterizer benchmark's W2 render, 128 x 128, 10,000 Gaussians, with the numba or torch
backend) idle and beside one busy 2-thread torch process (a matrix product in a loop), in
alternating rounds (idle, busy, idle, busy, ...), for this source tree and, with `--before
REVISION`, the tree at that revision, rounds interleaved across trees too. Each time is the
mean over the passes of a fixed wall time after two warm-up passes; the slowdown is the
median busy time over the median idle time of the same tree and backend (2x is the fair
share of 2 cores with one competitor).

Regenerate: velogauss bench library --before REVISION
Smoke test: velogauss bench library --quick --out /tmp/bench.md
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from velogauss.bench.step_ratio import export_revision

SECTION = "## Library use"
COMMAND = "velogauss bench library"
BACKENDS = ("numba", "torch")
ROUNDS, SECONDS = 5, 4.0
QUICK_ROUNDS, QUICK_SECONDS = 1, 0.2
_ROOT = Path(__file__).resolve().parents[2]
# The competitor: one torch process busy on both of a 2-core machine's cores.
_BUSY = "import torch\ntorch.set_num_threads(2)\na = torch.randn(384, 384)\nwhile True:\n    a @ a\n"
_SCRIPT = """
import json, sys, time
import torch
from velogauss.bench.raster import WORKLOADS, make_scene
from velogauss_fast.raster import rasterize

backend, seconds, workload = sys.argv[1], float(sys.argv[2]), sys.argv[3]
scene = make_scene(WORKLOADS[workload])
leaves = [scene[k].requires_grad_() for k in ("means", "quats", "scales", "opacities", "colors")]
weights = torch.rand(scene["height"], scene["width"], 3, generator=torch.Generator().manual_seed(1))

def one_pass():
    for t in leaves:
        t.grad = None
    image, _, _ = rasterize(**scene, backend=backend)
    (image * weights).sum().backward()

for _ in range(2):
    one_pass()
count, start = 0, time.perf_counter()
while count < 3 or time.perf_counter() - start < seconds:
    one_pass()
    count += 1
print(json.dumps({"mean_s": (time.perf_counter() - start) / count, "torch_threads": torch.get_num_threads()}))
"""
# The user's environment, without the thread variables of the caller's shell.
_THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_WAIT_POLICY")


def _environment(tree):
    env = {k: v for k, v in os.environ.items() if k not in _THREAD_VARS}
    return env | {"PYTHONPATH": str(tree)}


def _user_script(tree, backend, seconds, quick):
    """Seconds per pass of `_SCRIPT` importing velogauss from `tree`."""
    workload = "quick" if quick else "W2"
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, backend, str(seconds), workload], cwd=tree,
                          env=_environment(tree), capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        raise RuntimeError(f"the user's script ({tree}, {backend}) failed: {tail}")
    return json.loads(proc.stdout.strip().splitlines()[-1])["mean_s"]


def measure(trees, backends=BACKENDS, rounds=ROUNDS, seconds=SECONDS, quick=False, echo=print):
    """{(tree name, backend): {"idle": [s per pass per round], "busy": [...]}} for `trees` {name: path}."""
    times = {(name, b): {"idle": [], "busy": []} for name in trees for b in backends}
    for r in range(rounds):
        for (name, backend), row in times.items():
            row["idle"].append(_user_script(trees[name], backend, seconds, quick))
            busy = subprocess.Popen([sys.executable, "-c", _BUSY], env=_environment(trees[name]))
            try:
                time.sleep(1.0)  # the competitor has imported torch and is multiplying
                row["busy"].append(_user_script(trees[name], backend, seconds, quick))
            finally:
                busy.kill()
                busy.wait()
            echo(json.dumps({"round": r + 1, "tree": name, "backend": backend,
                             "idle_ms": 1e3 * row["idle"][-1], "busy_ms": 1e3 * row["busy"][-1]}))
    return times


def run(out_path="benchmarks/RESULTS.md", device="cpu", before=None, rounds=None, seconds=None, quick=False,
        echo=print):
    """Measure (`measure`) this tree, and the tree at git `before` when given, and write the
    "## Library use" section. Returns the measured times. CPU only (the contention is the CPU's)."""
    if device != "cpu":
        raise ValueError(f"--device: the library benchmark measures CPU threads; expected cpu, got {device!r}")
    rounds = (QUICK_ROUNDS if quick else ROUNDS) if rounds is None else rounds
    seconds = (QUICK_SECONDS if quick else SECONDS) if seconds is None else seconds
    if rounds < 1 or not seconds > 0:
        raise ValueError(f"rounds, seconds: expected >= 1 and > 0, got {rounds!r}, {seconds!r}")
    with tempfile.TemporaryDirectory(prefix="velogauss-library-") as tmp:
        trees = {"this tree": _ROOT}
        if before is not None:
            trees = {f"`{before}`": export_revision(before, Path(tmp) / "before"), **trees}
        times = measure(trees, rounds=rounds, seconds=seconds, quick=quick, echo=echo)
    from velogauss.bench.harness import machine, regenerate_command, write_section

    options = [f"--before {before}"] if before else []
    if rounds != (QUICK_ROUNDS if quick else ROUNDS):
        options.append(f"--rounds {rounds}")
    if seconds != (QUICK_SECONDS if quick else SECONDS):
        options.append(f"--seconds {seconds:g}")
    lines = ["| tree | backend | idle (ms) | beside a busy 2-thread torch process (ms) | slowdown |",
             "|---|---|---:|---:|---:|"]
    for (name, backend), row in times.items():
        idle, busy = statistics.median(row["idle"]), statistics.median(row["busy"])
        lines.append(f"| {name} | {backend} | {1e3 * idle:.1f} | {1e3 * busy:.1f} | {busy / idle:.2f}x |")
    workload = "the 12 x 12 render" if quick else "the W2 render (128 x 128, 10,000 Gaussians)"
    text = "\n\n".join([
        SECTION,
        f"A user's script (velogauss.bench.library: torch imported first, no thread policy set) timing forward + "
        f"backward of {workload}, idle and beside one busy 2-thread torch process, in {rounds} alternating "
        f"round(s) of {seconds:g} s per measurement, a fresh process each; medians over the rounds; slowdown = "
        "busy / idle of the same tree and backend (2x is the fair share of 2 cores with one competitor).",
        f"Machine: {machine()}.",
        f"Regenerate: `{regenerate_command(COMMAND, *options, quick=quick)}`",
        "\n".join(lines),
    ])
    write_section(out_path, SECTION, text)
    return times
