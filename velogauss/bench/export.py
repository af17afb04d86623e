"""Peak memory of `velogauss export RUN --time t` against t: inference keeps no autograd graph
and integrates in chunks of STAGE_CHUNK stage times, so memory stays flat as t grows.

Each export runs in a fresh process (the `velogauss` command itself); its peak resident set
comes from the kernel's accounting of that child (`os.wait4`, ru_maxrss). For comparison,
"before" runs the same model the way export ran before (autograd on, every stage's
coefficients at once) in a fresh process too. The run is a short training on the 16-pixel
`spin` scene of issue 13, made in a temporary folder.

Regenerate: velogauss bench export
"""

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from velogauss.bench.harness import machine, write_section

SECTION = "## Export: peak memory against the time exported"
TIMES = (1.0, 10.0, 100.0)
# "before", the export this benchmark compares with: gradients on, every stage's coefficients at once.
_BEFORE = """
import sys, torch
from velogauss.train.checkpoint import load_model
from velogauss_fast.motion import trajectory
trajectory.STAGE_CHUNK = 10**9
model, _ = load_model(sys.argv[1])
model.requires_grad_(True)
with torch.enable_grad():
    g = model.render_inputs_at(float(sys.argv[2]))
print(g["means"].requires_grad)
"""


def run(out_path="benchmarks/RESULTS.md", device="cpu"):
    """Train the tiny run, measure every export, write the section; return the rows."""
    if device != "cpu":
        raise ValueError(f"device: this benchmark measures the CPU resident set, got {device!r}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _velogauss("make-scene", "spin", "--out", tmp / "base16", "--resolution", 16, "--views", 3, "--times", 5)
        _velogauss("train", tmp / "base16", "--out", tmp / "run", "--no-eval", "--iterations", 4)
        rows = [("after: `velogauss export RUN --time %g`" % t, t,
                 *_measure([sys.executable, "-m", "velogauss", "export", tmp / "run", "--time", t, "--out",
                            tmp / "x.ply"])) for t in TIMES]
        rows += [("before: autograd on, all stages at once", t,
                  *_measure([sys.executable, "-c", _BEFORE, tmp / "run", t])) for t in TIMES]
    lines = [SECTION, "",
             "Peak resident memory of one process that loads the run's checkpoint and exports the Gaussians at "
             "time t (2,000 Gaussians, RK2, step 0.05: 20 steps per unit of time), each export in a fresh process "
             "(`os.wait4` ru_maxrss). \"after\" is the `velogauss export` command: no gradients, stage "
             "coefficients in chunks of `STAGE_CHUNK`. \"before\" is what export did before issue 13, run on the "
             "same checkpoint. The goal is a flat line in t; \"after\" grows only until t fills one chunk "
             "(t = 1 takes 40 RK2 stages, a chunk holds 256).", "",
             f"Machine: {machine()}.", "",
             "Regenerate: `velogauss bench export`", "",
             "| command | t | peak resident memory (MiB) | wall time (s) |", "|---|---|---|---|"]
    lines += [f"| {name} | {t:g} | {peak:.0f} | {wall:.1f} |" for name, t, peak, wall in rows]
    write_section(out_path, SECTION, "\n".join(lines))
    return rows


def _velogauss(*args):
    subprocess.run([sys.executable, "-m", "velogauss", *map(str, args)], check=True, capture_output=True)


def _measure(command):
    """(peak resident MiB, wall seconds) of `command` run to completion in a child process."""
    start = time.perf_counter()
    child = subprocess.Popen([str(c) for c in command], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{command}: failed: {child.stderr.read().decode()[-2000:]}")
    return usage.ru_maxrss / 1024, wall
