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

Each measurement runs in a fresh subprocess: one warm-up pass, then freed heap memory is
returned to the system (malloc_trim), the peak resident set size is reset
(/proc/self/clear_refs) and `repeats` timed passes follow; memory is the high-water mark
VmHWM above the resident size at the reset (on CUDA: torch.cuda.max_memory_allocated
above the allocation at the reset).
Parameters: `init_motion_params(default_rng(0), MotionSpec())` (the default sizes) plus
N(0, 0.1^2) on every entry (`_params`): a fresh model does not move.

Regenerate: velogauss bench motion
Smoke test: velogauss bench motion --quick --in-process --out /tmp/bench.md
"""

import json
import math
import statistics
import subprocess
import sys
from typing import NamedTuple

import numpy as np
import torch
from torch.func import jacrev, vmap

from velogauss.bench.harness import (device_section, machine, peak_above_mib, regenerate_command,
                                      reset_peak_memory, timed_passes, write_section)
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.params import params_to_torch
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.velocity import velocity_field
from velogauss_fast.physics.acceleration import acceleration_field
from velogauss_fast.physics.residuals import physics_residuals
from velogauss_core.motion import init_motion_params, MotionSpec

SECTION = "## Motion and residuals"
COMMAND = "velogauss bench motion"
CASES = ("trajectory-fwd", "trajectory-fwdbwd", "residuals-jvp-fwd", "residuals-jvp-fwdbwd",
         "residuals-jacrev-fwd", "residuals-jacrev-fwdbwd")
T_END = 0.75
T_COLLOCATION = 0.4


class Sizes(NamedTuple):
    n_particles: int  # trajectory
    n_steps: int  # RK2 steps over [0, T_END]
    n_points: int  # residual collocation points


FULL = Sizes(100_000, 30, 65_536)
# For smoke tests: seconds for every case.
QUICK = Sizes(256, 2, 64)


def reverse_mode_residuals(params, x, t, cfg):
    """(transport residual, divergence) via per-point reverse-mode Jacobians: the baseline.

    grad v and dv/dt of each point come from torch.func.jacrev of the single-point velocity
    v(x_i, t), vmapped over the points: what a straightforward autodiff implementation
    does (the reference does the same one point at a time with `autograd`).
    """
    t = torch.as_tensor(t, dtype=x.dtype, device=x.device)

    def v_point(xp, tp):
        return velocity_field(params, xp[None], tp, cfg)[0]

    grad_v, dv_dt = vmap(jacrev(v_point, argnums=(0, 1)), in_dims=(0, None))(x, t)
    v = velocity_field(params, x, t, cfg)
    r = dv_dt + (grad_v * v[:, None, :]).sum(-1) - acceleration_field(params, x, t, cfg)
    return r, grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def _params(dtype, device, requires_grad):
    """The default MotionSpec's parameters (seed 0), every entry shifted by N(0, 0.1^2).

    A fresh model starts still: the time network's last layer, Q and the ADF's last layer
    are zero, so velocities, accelerations and residuals are identically 0 and the
    forward-mode/jacrev comparison would be vacuous. The shift makes them all non-zero.
    """
    cfg = MotionSpec()
    rng = np.random.default_rng(0)
    params_np = _shifted(init_motion_params(rng, cfg), rng)
    return params_to_torch(params_np, dtype, device, requires_grad), cfg


def _shifted(params, rng, scale=0.1):
    """`params` (nested dicts, lists and tuples of arrays) plus N(0, scale^2) noise, same structure."""
    if isinstance(params, dict):
        return {k: _shifted(v, rng, scale) for k, v in params.items()}
    if isinstance(params, (list, tuple)):
        return type(params)(_shifted(v, rng, scale) for v in params)
    return params + rng.normal(scale=scale, size=np.shape(params))


def leaves(params):
    """The tensors of a motion parameter dict (nested dicts, lists and tuples), in a fixed order."""
    if isinstance(params, dict):
        return [t for v in params.values() for t in leaves(v)]
    if isinstance(params, (list, tuple)):
        return [t for v in params for t in leaves(v)]
    return [params]


def _step_size(n_steps):
    """h with exactly n_steps steps of VG-INTEG over [0, T_END] (ceil(T_END / h) == n_steps)."""
    h = T_END / n_steps * (1 + 1e-9)
    assert math.ceil(T_END / h) == n_steps
    return h


def _collocation_points(n, dtype, device, seed=1):
    g = torch.Generator().manual_seed(seed)
    return (2 * torch.rand(n, 3, generator=g, dtype=torch.float64) - 1).to(dtype=dtype, device=device)


def _workload(case, device, sizes):
    """The zero-argument function that one timed pass of `case` at `sizes` calls."""
    backward = case.endswith("fwdbwd")
    params, cfg = _params(torch.float32, device, requires_grad=backward)
    tensors = leaves(params)
    g = torch.Generator().manual_seed(2)
    if case.startswith("trajectory"):
        n = sizes.n_particles
        x0 = (2 * torch.rand(n, 3, generator=g) - 1).to(device).requires_grad_(backward)
        q0 = torch.randn(n, 4, generator=g).to(device).requires_grad_(backward)
        s0 = (0.005 + 0.05 * torch.rand(n, 3, generator=g)).to(device).requires_grad_(backward)
        cot = [torch.randn(n, k, generator=g).to(device) for k in (3, 4, 3)]
        tensors += [x0, q0, s0]
        h = _step_size(sizes.n_steps)

        def forward():
            z = physics_code(params, x0, cfg)
            return base_state(params, x0, q0, s0, z, T_END, h, "rk2", cfg)

        def loss(out):
            return sum((o * c).sum() for o, c in zip(out, cot))
    else:
        x = _collocation_points(sizes.n_points, torch.float32, device)
        impl = physics_residuals if "-jvp-" in case else reverse_mode_residuals

        def forward():
            return impl(params, x, T_COLLOCATION, cfg)

        def loss(out):
            r, div = out
            return (r * r).sum(-1).mean() + (div * div).mean()

    def step():
        for leaf in tensors:
            leaf.grad = None
        if backward:
            loss(forward()).backward()
        else:
            with torch.no_grad():  # torch.func transforms still differentiate inside
                forward()
        if device != "cpu":
            torch.cuda.synchronize()

    return step


def _worker(case, repeats, device, threads, quick):
    """Time `repeats` passes of one case in this (fresh) process."""
    if threads:
        torch.set_num_threads(threads)
    step = _workload(case, device, QUICK if quick else FULL)
    step()  # warm-up: allocator pools, lazy imports, one-time kernels
    baseline = reset_peak_memory(device)
    times = timed_passes(step, repeats)
    return {"case": case, "times": times, "median_s": statistics.median(times),
            "peak_mib": peak_above_mib(device, baseline), "threads": torch.get_num_threads()}


def measure(case, repeats, device, threads, quick=False, in_process=False):
    """Time one case in a fresh interpreter (this module run as a script) or in this one;
    returns its result dict, or {"case", "skipped": why} when the fresh interpreter failed."""
    if in_process:
        return _worker(case, repeats, device, threads, quick)
    arguments = {"case": case, "repeats": repeats, "device": device, "threads": threads or 0, "quick": quick}
    proc = subprocess.run([sys.executable, "-m", "velogauss.bench.motion", json.dumps(arguments)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        return {"case": case, "skipped": f"failed: {tail[:160]}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def residual_difference(device, dtype, n_points=FULL.n_points):
    """max |forward-mode - jacrev| over the transport residual and the divergence, and the
    largest |transport residual| (for scale), on the benchmark's collocation points."""
    params, cfg = _params(dtype, device, requires_grad=False)
    x = _collocation_points(n_points, dtype, device)
    r1, d1 = physics_residuals(params, x, T_COLLOCATION, cfg)
    r2, d2 = reverse_mode_residuals(params, x, T_COLLOCATION, cfg)
    diff = max(float((r1 - r2).abs().max()), float((d1 - d2).abs().max()))
    return diff, float(r1.abs().max()), float(d1.abs().max())


def _fmt_row(label, r, base=None):
    if "skipped" in r:
        return f"| {label} | - | - | - | - | {r['skipped']} |"
    ratio_t = ratio_m = "-"
    if base is not None and "skipped" not in base:
        ratio_t = f"{r['median_s'] / base['median_s']:.1f}x"
        ratio_m = f"{r['peak_mib'] / max(base['peak_mib'], 1e-9):.1f}x"
    return (f"| {label} | {r['median_s']:.3f} | {ratio_t} | {r['peak_mib']:.0f} | {ratio_m} | "
            f"{len(r['times'])} runs, {r['threads']} threads |")


def run(out="benchmarks/RESULTS.md", device="cpu", repeats=5, threads=None, echo=print, quick=False,
        in_process=False):
    """Run every case, write the "## Motion and residuals" section of `out`; return the results.

    repeats: timed passes per case (after one warm-up); threads: torch CPU threads in the
    workers (None: torch's default); quick: the QUICK sizes (smoke tests); in_process:
    measure in this process instead of a fresh one per case (smoke tests; memory then
    includes earlier cases' leftovers).
    """
    if repeats < 1:
        raise ValueError(f"repeats: expected a positive int, got {repeats!r}")
    sizes = QUICK if quick else FULL
    results = {}
    for case in CASES:
        results[case] = measure(case, repeats, device, threads, quick, in_process)
        echo(json.dumps({k: v for k, v in results[case].items() if k != "times"}))
    diff32, r32, d32 = residual_difference(device, torch.float32, sizes.n_points)
    diff64, _, _ = residual_difference(device, torch.float64, sizes.n_points)
    results["max_abs_difference"] = {"float32": diff32, "float64": diff64}
    echo(json.dumps(results["max_abs_difference"]))
    header = "| case | median (s) | time / forward-mode | peak memory above start (MiB) | memory / forward-mode | note |"
    rows = [header, "|---|---|---|---|---|---|"]
    trajectory = f"base_state RK2, {sizes.n_particles:,} particles x {sizes.n_steps} steps"
    rows.append(_fmt_row(f"{trajectory}: forward", results["trajectory-fwd"]))
    rows.append(_fmt_row(f"{trajectory}: forward + backward", results["trajectory-fwdbwd"]))
    for kind, label in (("fwd", "forward"), ("fwdbwd", "forward + backward")):
        base = results[f"residuals-jvp-{kind}"]
        rows.append(_fmt_row(f"residuals, {sizes.n_points:,} points, forward-mode (ours): {label}", base, base))
        rows.append(_fmt_row(f"residuals, {sizes.n_points:,} points, jacrev per point (vmapped): {label}",
                             results[f"residuals-jacrev-{kind}"], base))
    command = regenerate_command(COMMAND, quick=quick, device=device, threads=threads)
    text = "\n\n".join([
        device_section(SECTION, device),
        f"{device.upper()}, float32, `MotionSpec()` defaults, parameters "
        f"`init_motion_params(default_rng(0), MotionSpec())` shifted by N(0, 0.1^2) (so that "
        f"velocities and residuals are not identically 0). Trajectory: `physics_code` + "
        f"`base_state` (velocity + RK2, state (x, q, log s)) to t = {T_END} in {sizes.n_steps} steps; "
        f"backward = gradients of all motion parameters and x0, q0, s0 (random cotangent). "
        f"Residuals: transport + divergence at {sizes.n_points:,} points uniform in [-1, 1]^3, "
        f"t = {T_COLLOCATION}; backward = the loss mean(|r|^2) + mean(div^2) to the parameters. "
        f"Median of the timed runs after one warm-up, each case in a fresh process; memory is "
        f"the resident-set high-water mark during the timed runs above the resident size before "
        f"them (freed heap memory trimmed first; on CUDA the allocator's peak).",
        f"Forward-mode vs jacrev, max abs difference over r and div: {diff32:.2e} in float32 "
        f"(max |r| = {r32:.2e}, max |div| = {d32:.2e}), {diff64:.2e} in float64.",
        f"Machine: {machine(device)}.",
        f"Regenerate: `{command}`",
        "\n".join(rows),
    ])
    write_section(str(out), device_section(SECTION, device), text)
    return results


if __name__ == "__main__":  # `measure`'s fresh interpreter: `_worker`'s arguments in, its result out, as JSON
    print(json.dumps(_worker(**json.loads(sys.argv[1]))))
