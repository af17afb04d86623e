"""Motion and physics-residual benchmark: time and peak memory of the torch fast path.

Two measurements, float32, CPU unless --device says otherwise:

* trajectory -- z = physics_code(x0) and base_state (velocity + RK2, (x, q, log s)
  jointly) for 100k particles over 30 steps: forward, and forward + backward (gradients
  of all motion parameters and of x0, q0, s0 through a random cotangent);
* residuals  -- transport + divergence residuals (VG-TRANSPORT, VG-DIV) at 65,536
  collocation points: `velogauss_fast.physics.residuals.physics_residuals` (analytic
  A(w) + forward-mode JVPs through the code network) against a reverse-mode baseline,
  torch.func.jacrev of the per-point velocity vmapped over the points; forward, and
  forward + backward of the physics loss mean(|r|^2) + mean(div^2) to the parameters.
  Both are also evaluated once on the same inputs and their largest difference reported.

Each measurement runs in a fresh subprocess: one warm-up pass, then the peak resident set
size is reset (/proc/self/clear_refs) and `repeats` timed passes follow; memory is the
high-water mark VmHWM above the resident size at the reset (on CUDA:
torch.cuda.max_memory_allocated above the allocation at the reset).
Parameters: `init_motion_params(default_rng(0), MotionConfig())` (the default sizes).

Regenerate: python -m velogauss.bench.motion   (or: velogauss bench motion)
"""

import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys
import time

import numpy as np
import torch
from torch.func import jacrev, vmap

from velogauss.bench.raster import _machine, _status_kib
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.params import params_to_torch
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.velocity import _velocity_field
from velogauss_fast.physics.acceleration import acceleration_field
from velogauss_fast.physics.residuals import physics_residuals
from velogauss_ref.motion.config import MotionConfig, init_motion_params

SECTION = "## Motion and residuals"
COMMAND = "python -m velogauss.bench.motion"
CASES = ("trajectory-fwd", "trajectory-fwdbwd", "residuals-jvp-fwd", "residuals-jvp-fwdbwd",
         "residuals-jacrev-fwd", "residuals-jacrev-fwdbwd")
N_PARTICLES = 100_000
N_STEPS = 30
T_END = 0.75
N_POINTS = 65_536
T_COLLOCATION = 0.4


def reverse_mode_residuals(params, x, t, cfg):
    """(transport residual, divergence) via per-point reverse-mode Jacobians: the baseline.

    grad v and dv/dt of each point come from torch.func.jacrev of the single-point velocity
    v(x_i, t), vmapped over the points: what a straightforward autodiff implementation
    does (the reference does the same one point at a time with `autograd`).
    """
    t = torch.as_tensor(t, dtype=x.dtype, device=x.device)

    def v_point(xp, tp):
        return _velocity_field(params, xp[None], tp, cfg)[0]

    grad_v, dv_dt = vmap(jacrev(v_point, argnums=(0, 1)), in_dims=(0, None))(x, t)
    v = _velocity_field(params, x, t, cfg)
    r = dv_dt + (grad_v * v[:, None, :]).sum(-1) - acceleration_field(params, x, t, cfg)
    return r, grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def _params(dtype, device, requires_grad):
    cfg = MotionConfig()
    params_np = init_motion_params(np.random.default_rng(0), cfg)
    return params_to_torch(params_np, dtype, device, requires_grad), cfg


def _leaves(params):
    if isinstance(params, dict):
        return [t for v in params.values() for t in _leaves(v)]
    if isinstance(params, (list, tuple)):
        return [t for v in params for t in _leaves(v)]
    return [params]


def _step_size():
    """h with exactly N_STEPS steps of VG-INTEG over [0, T_END] (ceil(T_END / h) == N_STEPS)."""
    h = T_END / N_STEPS * (1 + 1e-9)
    assert math.ceil(T_END / h) == N_STEPS
    return h


def _collocation_points(n, dtype, device, seed=1):
    g = torch.Generator().manual_seed(seed)
    return (2 * torch.rand(n, 3, generator=g, dtype=torch.float64) - 1).to(dtype=dtype, device=device)


def _workload(case, device):
    """The zero-argument function that one timed pass of `case` calls."""
    backward = case.endswith("fwdbwd")
    params, cfg = _params(torch.float32, device, requires_grad=backward)
    leaves = _leaves(params)
    g = torch.Generator().manual_seed(2)
    if case.startswith("trajectory"):
        n = N_PARTICLES
        x0 = (2 * torch.rand(n, 3, generator=g) - 1).to(device).requires_grad_(backward)
        q0 = torch.randn(n, 4, generator=g).to(device).requires_grad_(backward)
        s0 = (0.005 + 0.05 * torch.rand(n, 3, generator=g)).to(device).requires_grad_(backward)
        cot = [torch.randn(n, k, generator=g).to(device) for k in (3, 4, 3)]
        leaves += [x0, q0, s0]
        h = _step_size()

        def forward():
            z = physics_code(params, x0, cfg)
            return base_state(params, x0, q0, s0, z, T_END, h, "rk2", cfg)

        def loss(out):
            return sum((o * c).sum() for o, c in zip(out, cot))
    else:
        x = _collocation_points(N_POINTS, torch.float32, device)
        impl = physics_residuals if "-jvp-" in case else reverse_mode_residuals

        def forward():
            return impl(params, x, T_COLLOCATION, cfg)

        def loss(out):
            r, div = out
            return (r * r).sum(-1).mean() + (div * div).mean()

    def step():
        for leaf in leaves:
            leaf.grad = None
        if backward:
            loss(forward()).backward()
        else:
            with torch.no_grad():  # torch.func transforms still differentiate inside
                forward()
        if device != "cpu":
            torch.cuda.synchronize()

    return step


def _worker(case, repeats, device, threads):
    """Time `repeats` passes of one case in this (fresh) process."""
    if threads:
        torch.set_num_threads(threads)
    step = _workload(case, device)
    step()  # warm-up: allocator pools, lazy imports, one-time kernels
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current resident size
    rss0 = _status_kib("VmRSS")
    if device != "cpu":
        torch.cuda.reset_peak_memory_stats()
        cuda0 = torch.cuda.memory_allocated()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    peak = (_status_kib("VmHWM") - rss0) / 1024
    if device != "cpu":
        peak = (torch.cuda.max_memory_allocated() - cuda0) / 2**20
    return {"case": case, "times": times, "median_s": statistics.median(times), "peak_mib": peak,
            "threads": torch.get_num_threads()}


def _measure(case, repeats, device, threads):
    """Run one case in a fresh interpreter; returns its result dict."""
    cmd = [sys.executable, "-m", "velogauss.bench.motion", "--worker", case, "--repeats", str(repeats),
           "--device", device, "--threads", str(threads or 0)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        return {"case": case, "skipped": f"failed: {tail[:160]}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def residual_difference(device, dtype, n_points=N_POINTS):
    """max |forward-mode - jacrev| over the transport residual and the divergence, and the
    largest |transport residual| (for scale), on the benchmark's collocation points."""
    params, cfg = _params(dtype, device, requires_grad=False)
    x = _collocation_points(n_points, dtype, device)
    r1, d1 = physics_residuals(params, x, T_COLLOCATION, cfg)
    r2, d2 = reverse_mode_residuals(params, x, T_COLLOCATION, cfg)
    diff = max(float((r1 - r2).abs().max()), float((d1 - d2).abs().max()))
    return diff, float(r1.abs().max()), float(d1.abs().max())


def _write_section(out_path, text):
    """Replace (or append) this module's section of out_path, leaving other sections alone."""
    old = ""
    if os.path.exists(out_path):
        with open(out_path) as f:
            old = f.read()
    if not old.strip():
        old = "# Benchmarks\n"
    pattern = re.compile(rf"^{re.escape(SECTION)}\n.*?(?=^## |\Z)", re.M | re.S)
    section = text.rstrip("\n") + "\n\n"
    new = pattern.sub(lambda _: section, old, count=1) if pattern.search(old) else old.rstrip("\n") + "\n\n" + section
    os.makedirs(os.path.dirname(out_path) or ".", exist_ok=True)
    with open(out_path, "w") as f:
        f.write(new.rstrip("\n") + "\n")


def _fmt_row(label, r, base=None):
    if "skipped" in r:
        return f"| {label} | - | - | - | - | {r['skipped']} |"
    ratio_t = ratio_m = "-"
    if base is not None and "skipped" not in base:
        ratio_t = f"{r['median_s'] / base['median_s']:.1f}x"
        ratio_m = f"{r['peak_mib'] / max(base['peak_mib'], 1e-9):.1f}x"
    return (f"| {label} | {r['median_s']:.3f} | {ratio_t} | {r['peak_mib']:.0f} | {ratio_m} | "
            f"{len(r['times'])} runs, {r['threads']} threads |")


def run(out="benchmarks/RESULTS.md", device="cpu", repeats=5, threads=None, echo=print):
    """Run every case, write the "## Motion and residuals" section of `out`; return the results.

    repeats: timed passes per case (after one warm-up); threads: torch CPU threads in the
    workers (None: torch's default).
    """
    if repeats < 1:
        raise ValueError(f"repeats: expected a positive int, got {repeats!r}")
    results = {}
    for case in CASES:
        results[case] = _measure(case, repeats, device, threads)
        echo(json.dumps({k: v for k, v in results[case].items() if k != "times"}))
    diff32, r32, d32 = residual_difference(device, torch.float32)
    diff64, _, _ = residual_difference(device, torch.float64)
    results["max_abs_difference"] = {"float32": diff32, "float64": diff64}
    echo(json.dumps(results["max_abs_difference"]))
    header = "| case | median (s) | time / forward-mode | peak memory above start (MiB) | memory / forward-mode | note |"
    rows = [header, "|---|---|---|---|---|---|"]
    rows.append(_fmt_row(f"base_state RK2, {N_PARTICLES:,} particles x {N_STEPS} steps: forward",
                         results["trajectory-fwd"]))
    rows.append(_fmt_row(f"base_state RK2, {N_PARTICLES:,} particles x {N_STEPS} steps: forward + backward",
                         results["trajectory-fwdbwd"]))
    for kind, label in (("fwd", "forward"), ("fwdbwd", "forward + backward")):
        base = results[f"residuals-jvp-{kind}"]
        rows.append(_fmt_row(f"residuals, {N_POINTS:,} points, forward-mode (ours): {label}", base, base))
        rows.append(_fmt_row(f"residuals, {N_POINTS:,} points, jacrev per point (vmapped): {label}",
                             results[f"residuals-jacrev-{kind}"], base))
    text = "\n\n".join([
        SECTION,
        f"{device.upper()}, float32, `MotionConfig()` defaults, parameters "
        f"`init_motion_params(default_rng(0), MotionConfig())`. Trajectory: `physics_code` + "
        f"`base_state` (velocity + RK2, state (x, q, log s)) to t = {T_END} in {N_STEPS} steps; "
        f"backward = gradients of all motion parameters and x0, q0, s0 (random cotangent). "
        f"Residuals: transport + divergence at {N_POINTS:,} points uniform in [-1, 1]^3, "
        f"t = {T_COLLOCATION}; backward = the loss mean(|r|^2) + mean(div^2) to the parameters. "
        f"Median of the timed runs after one warm-up, each case in a fresh process; memory is "
        f"the resident-set high-water mark during the timed runs above the resident size before "
        f"them.",
        f"Forward-mode vs jacrev, max abs difference over r and div: {diff32:.2e} in float32 "
        f"(max |r| = {r32:.2e}, max |div| = {d32:.2e}), {diff64:.2e} in float64.",
        f"Machine: {_machine()}.",
        f"Regenerate: `{COMMAND}`" + (f" `--threads {threads}`" if threads else ""),
        "\n".join(rows),
    ])
    _write_section(str(out), text)
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", metavar="CASE", choices=CASES, help=argparse.SUPPRESS)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    parser.add_argument("--out", default="benchmarks/RESULTS.md")
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(_worker(args.worker, args.repeats, args.device, args.threads)))
        return
    run(args.out, args.device, args.repeats, args.threads or None)


if __name__ == "__main__":
    main()
