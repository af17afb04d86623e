"""Rasterizer benchmark: forward+backward time and peak memory of four renderers.

Methods, all on the same random scenes (float32, CPU unless --device says otherwise):

* numba     -- velogauss_fast.raster.rasterize(backend="numba"): compiled Gaussian-major
               compositing, analytic backward, no pair table (CPU only);
* torch     -- rasterize(backend="torch"): vectorised compositing over the sorted pair
               table, analytic backward (any device);
* gsplat    -- rasterize(backend="gsplat"): gsplat's CUDA kernels (CUDA with gsplat only);
* autograd  -- the torch backend's projection, pair table and compositing left to
               autograd (velogauss_fast.raster.COMPOSITES["autograd"]): what the
               formulation costs without a hand-written backward;
* dense     -- a straightforward all-pairs renderer: every Gaussian at every pixel as
               dense (P, N) tensors, the approach of simple pure-torch splatting code
               (same VG-ALPHA/VG-BLEND semantics, box test included);
* reference -- velogauss_ref.raster.rasterize with autograd gradients (NumPy, per-pixel
               loop), on the smallest workload only.

Each workload is measured in rounds; a round runs every method once, in turn, each in a
fresh subprocess (dense and reference in the first round only): one warm-up pass, then the memory
the allocator caches is returned to the system (malloc_trim), the peak resident set size
is reset (/proc/self/clear_refs) and `repeats` timed passes follow; memory is the
high-water mark VmHWM minus the resident size at the reset (the scene, the interpreter
and torch are excluded), and the absolute VmHWM is reported too. On CUDA, memory is
torch.cuda.max_memory_allocated above the allocation at the reset. "image sum" is the
sum of the rendered image: equal across methods up to float32 rounding (the reference
renders in float64), so a fast but wrong method shows. --threads sets torch's CPU threads
in the workers: on a machine with busy cores, give no more than the idle ones (torch's
spinning workers otherwise slow every pass down many times over).

Regenerate: velogauss bench raster
Smoke test: velogauss bench raster --quick --in-process --out /tmp/bench.md
"""

import json
import math
import statistics
import subprocess
import sys
from dataclasses import dataclass

import torch

from velogauss.bench.harness import (device_section, machine, peak_above_mib, regenerate_command,
                                      reset_peak_memory, timed_passes, write_section)
from velogauss.memory import status_kib
from velogauss_fast.backends import gsplat_available
from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN

SECTION = "## Rasterizer"
COMMAND = "velogauss bench raster"


@dataclass(frozen=True)
class Workload:
    name: str
    width: int
    height: int
    n_gaussians: int


WORKLOADS = {
    "W1": Workload("W1", 64, 64, 2_000),
    "W2": Workload("W2", 128, 128, 10_000),
    "W3": Workload("W3", 256, 256, 50_000),
    "W4": Workload("W4", 400, 400, 100_000),
    # For smoke tests: seconds for every method, the reference included.
    "quick": Workload("quick", 12, 12, 24),
}
DEFAULT_WORKLOADS = ("W1", "W2", "W3", "W4")
METHODS = ("numba", "torch", "gsplat", "autograd", "dense", "reference")
# The per-pixel NumPy reference is far too slow beyond the smallest workload.
REFERENCE_WORKLOADS = ("W1", "quick")
# Peak bytes per (pixel, Gaussian) element of the dense renderer's forward + backward, as
# measured on W1: a dense run whose P * N elements need more than the memory limit is skipped.
DENSE_BYTES_PER_ELEMENT = 128


def make_scene(workload, seed=0, dtype=torch.float32, device="cpu"):
    """A random scene of `workload.n_gaussians` Gaussians in front of a 60-degree camera.

    Means fill the view frustum between depths 2 and 6; each scale axis is drawn so that
    its screen-space standard deviation is log-uniform in [0.2, 2] px (before EPS2D), so a
    Gaussian covers a few to tens of pixels at every resolution. Opacities U(0.1, 0.9),
    colours U(0, 1), random rotations. Returns the keyword arguments of `rasterize`.
    """
    g = torch.Generator().manual_seed(seed)
    n, w, h = workload.n_gaussians, workload.width, workload.height
    f = 0.5 * w / math.tan(math.radians(30.0))
    z = 2.0 + 4.0 * torch.rand(n, generator=g, dtype=torch.float64)
    u = w * torch.rand(n, generator=g, dtype=torch.float64)
    v = h * torch.rand(n, generator=g, dtype=torch.float64)
    means = torch.stack([(u - 0.5 * w) * z / f, (v - 0.5 * h) * z / f, z], dim=1)
    sigma_px = torch.exp(math.log(0.2) + math.log(10.0) * torch.rand(n, 3, generator=g, dtype=torch.float64))
    scene = {
        "means": means,
        "quats": torch.randn(n, 4, generator=g, dtype=torch.float64),
        "scales": sigma_px * z[:, None] / f,
        "opacities": 0.1 + 0.8 * torch.rand(n, generator=g, dtype=torch.float64),
        "colors": torch.rand(n, 3, generator=g, dtype=torch.float64),
        "viewmat": torch.eye(4, dtype=torch.float64),
        "K": torch.tensor([[f, 0.0, 0.5 * w], [0.0, f, 0.5 * h], [0.0, 0.0, 1.0]], dtype=torch.float64),
    }
    scene = {k: t.to(dtype=dtype, device=device) for k, t in scene.items()}
    scene.update(width=w, height=h)
    return scene


def dense_rasterize(means, quats, scales, opacities, colors, viewmat, K, width, height, background=None):
    """All-pairs renderer: every valid Gaussian evaluated at every pixel as (P, N) tensors.

    The textbook pure-torch splatter, kept only as the benchmark's baseline: same
    projection, box test, VG-ALPHA skip rules and VG-BLEND early termination as
    `velogauss_fast.raster.rasterize`, so it renders the same image, but its time and
    memory grow with pixels x Gaussians. Gradients come from autograd.
    """
    from velogauss_fast.covariance import covariance_3d
    from velogauss_fast.projection import project_gaussians

    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height)
    ids = torch.nonzero(proj["valid"]).squeeze(1)
    ids = ids[torch.argsort(proj["depth"][ids].detach(), stable=True)]
    mu, conic, r = proj["mean2d"][ids], proj["conic"][ids], proj["radius"][ids].to(means.dtype)
    jj, ii = torch.meshgrid(
        torch.arange(width, dtype=means.dtype, device=means.device),
        torch.arange(height, dtype=means.dtype, device=means.device),
        indexing="xy",
    )
    centres = torch.stack([jj.reshape(-1), ii.reshape(-1)], dim=1) + 0.5  # [P, 2]
    du = centres[:, None, 0] - mu[None, :, 0]  # [P, N]
    dv = centres[:, None, 1] - mu[None, :, 1]
    in_box = (du.abs() <= r) & (dv.abs() <= r)
    sigma = 0.5 * (conic[:, 0] * du * du + conic[:, 2] * dv * dv) + conic[:, 1] * du * dv
    alpha = torch.clamp(opacities[ids] * torch.exp(-sigma), max=ALPHA_MAX)
    alpha = torch.where(in_box & (sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))
    t_incl = torch.cumprod(1 - alpha, dim=1)
    blended = (alpha > 0) & (t_incl >= TRANSMITTANCE_MIN)
    t_excl = torch.cat([torch.ones_like(t_incl[:, :1]), t_incl[:, :-1]], dim=1)
    w = torch.where(blended, alpha * t_excl, torch.zeros_like(alpha))
    T = torch.prod(torch.where(blended, 1 - alpha, torch.ones_like(alpha)), dim=1)
    if background is None:
        background = means.new_zeros(3)
    image = w @ colors[ids] + T[:, None] * background
    return image.reshape(height, width, 3), (1 - T).reshape(height, width, 1)


def _renderer(method):
    """The function (scene tensors...) -> (image, alpha) that `method` times."""
    if method in ("numba", "torch", "gsplat"):
        from velogauss_fast.raster import rasterize

        return lambda **s: rasterize(**s, backend=method)[:2]
    if method == "autograd":
        from velogauss_fast.raster import COMPOSITES, render_with_composite

        return lambda **s: render_with_composite(**s, background=s["means"].new_zeros(3), sh_degree=None,
                                                 composite=COMPOSITES["autograd"])[:2]
    if method == "dense":
        return lambda **s: dense_rasterize(**s)[:2]
    if method == "reference":
        return _reference_renderer()
    raise ValueError(f"method: expected one of {METHODS}, got {method!r}")


def _reference_renderer():
    """The NumPy reference (float64) wrapped so its autograd gradients land in the torch leaves."""
    from autograd import make_vjp
    from autograd.builtins import tuple as traced_tuple

    from velogauss_ref.raster import rasterize as ref_rasterize

    names = ("means", "quats", "scales", "opacities", "colors")

    def to_numpy(t):
        return t.detach().double().cpu().numpy()

    class _Ref(torch.autograd.Function):
        @staticmethod
        def forward(ctx, width, height, viewmat, K, *leaves):
            vm, k = to_numpy(viewmat), to_numpy(K)

            def render(xs):
                image, alpha, _ = ref_rasterize(*xs, vm, k, width, height)
                return traced_tuple((image, alpha))  # a plain tuple is invisible to autograd

            ctx.vjp, (image, alpha) = make_vjp(render)([to_numpy(t) for t in leaves])
            ctx.like = leaves[0]
            return ctx.like.new_tensor(image), ctx.like.new_tensor(alpha)

        @staticmethod
        def backward(ctx, g_image, g_alpha):
            grads = ctx.vjp((to_numpy(g_image), to_numpy(g_alpha)))
            return (None, None, None, None) + tuple(ctx.like.new_tensor(g) for g in grads)

    def run(**s):
        return _Ref.apply(s["width"], s["height"], s["viewmat"], s["K"], *(s[k] for k in names))

    return run


def _worker(method, workload, repeats, device, threads=0):
    """Time `repeats` forward+backward passes of one method in this (fresh) process.

    threads: torch CPU threads (0: torch's default, one per core); on a machine whose cores
    are busy, give no more than the free ones, since torch's OpenMP workers spin against
    each other.
    """
    if threads:
        torch.set_num_threads(threads)
    scene = make_scene(WORKLOADS[workload], device=device)
    leaves = {k: scene[k].requires_grad_() for k in ("means", "quats", "scales", "opacities", "colors")}
    render = _renderer(method)
    g = torch.Generator().manual_seed(1)
    v_image = torch.rand(scene["height"], scene["width"], 3, generator=g).to(device)
    v_alpha = torch.rand(scene["height"], scene["width"], 1, generator=g).to(device)

    def step():
        for t in leaves.values():
            t.grad = None
        image, alpha = render(**scene)
        ((image * v_image).sum() + (alpha * v_alpha).sum()).backward()
        if device != "cpu":
            torch.cuda.synchronize()
        return image

    image = step()  # warm-up: allocator pools, lazy imports, one-time kernels
    checksum = float(image.detach().double().sum())
    baseline = reset_peak_memory(device)
    times = timed_passes(step, repeats)
    return {
        "method": method,
        "workload": workload,
        "times": times,
        "median_s": statistics.median(times),
        "peak_rss_mib": status_kib("VmHWM") / 1024,
        "peak_above_start_mib": peak_above_mib(device, baseline),
        "checksum": checksum,
        "threads": torch.get_num_threads(),
    }


def default_method(device):
    """The method `rasterize(backend="auto")` amounts to on `device`; ratios are taken to it."""
    if torch.device(device).type == "cpu":
        return "numba"
    return "gsplat" if gsplat_available(device) else "torch"


def _skip_reason(method, workload, memory_limit_gib, device="cpu"):
    wl = WORKLOADS[workload]
    if method == "numba" and torch.device(device).type != "cpu":
        return "CPU only"
    if method == "gsplat" and not gsplat_available(device):
        return "needs CUDA and the gsplat package"
    if method == "reference" and workload not in REFERENCE_WORKLOADS:
        return "reference timed on W1 only (per-pixel Python loop)"
    if method == "dense":
        need = wl.width * wl.height * wl.n_gaussians * DENSE_BYTES_PER_ELEMENT / 2**30
        if need > memory_limit_gib:
            return f"does not fit: needs ~{need:.0f} GiB for (P, N) tensors > {memory_limit_gib:g} GiB"
    return None


def measure(method, workload, repeats, device, threads=0, in_process=False):
    """Time one (method, workload) in a fresh interpreter (this module run as a script) or in
    this one; returns its result dict, or {"method", "workload", "skipped": why} when the
    fresh interpreter failed."""
    if in_process:
        return _worker(method, workload, repeats, device, threads)
    arguments = {"method": method, "workload": workload, "repeats": repeats, "device": device, "threads": threads}
    proc = subprocess.run([sys.executable, "-m", "velogauss.bench.raster", json.dumps(arguments)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or [f"exit code {proc.returncode}"])[-1]
        return {"method": method, "workload": workload, "skipped": f"failed: {tail[:120]}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _table(results, workloads, methods, device="cpu"):
    by = {(r["method"], r["workload"]): r for r in results}
    default = default_method(device)
    lines = [
        "| workload | method | median fwd+bwd (s) | time / default | peak RSS (MiB) | peak above start (MiB) "
        "| memory / default | image sum | note |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for w in workloads:
        wl = WORKLOADS[w]
        base = by.get((default, w))
        for m in methods:
            r = by.get((m, w))
            label = f"{w} {wl.width}x{wl.height}, {wl.n_gaussians:,} G"
            if r is None:
                continue
            if "skipped" in r:
                lines.append(f"| {label} | {m} | - | - | - | - | - | - | {r['skipped']} |")
                continue
            ratio_t = ratio_m = "-"
            if base is not None and "skipped" not in base:
                ratio_t = f"{r['median_s'] / base['median_s']:.1f}x"
                ratio_m = f"{r['peak_above_start_mib'] / max(base['peak_above_start_mib'], 1e-9):.1f}x"
            note = f"{len(r['times'])} runs in {r['rounds']} rounds, {r['threads']} threads"
            lines.append(
                f"| {label} | {m} | {r['median_s']:.3f} | {ratio_t} | {r['peak_rss_mib']:.0f} | "
                f"{r['peak_above_start_mib']:.0f} | {ratio_m} | {r['checksum']:.4f} | {note} |"
            )
    return "\n".join(lines)


def _command(workloads, methods, device, threads, rounds=3):
    """The command line that regenerates a table of these workloads, methods, device, threads and rounds."""
    options = []
    if tuple(workloads) != DEFAULT_WORKLOADS:
        options.append("--workloads " + ",".join(workloads))
    if tuple(methods) != METHODS:
        options.append("--methods " + ",".join(methods))
    if rounds != 3:
        options.append(f"--rounds {rounds}")
    return regenerate_command(COMMAND, *options, device=device, threads=threads)


# Methods too slow to repeat: measured in the first round only.
SINGLE_ROUND = ("dense", "reference")


def _repeats(method, workload):
    """Default timed passes per measurement."""
    if method == "reference" or workload == "quick":
        return 1
    if method == "dense" and workload != "W1":
        return 2
    return 3 if workload in ("W1", "W2") else 2


def _merge(runs):
    """One result from the measurements of a (method, workload) over the rounds: the
    median over every timed pass, the median peak memory over the processes."""
    merged = dict(runs[0])
    merged["times"] = [t for r in runs for t in r["times"]]
    merged["median_s"] = statistics.median(merged["times"])
    for key in ("peak_rss_mib", "peak_above_start_mib"):
        merged[key] = statistics.median(r[key] for r in runs)
    merged["rounds"] = len(runs)
    return merged


def run(out_path="benchmarks/RESULTS.md", workloads=DEFAULT_WORKLOADS, methods=METHODS, repeats=None,
        memory_limit_gib=24.0, device="cpu", echo=print, threads=0, in_process=False, rounds=3):
    """Benchmark `methods` on `workloads` and write the "## Rasterizer" section of out_path.

    Each workload is measured in `rounds` rounds, each running every method once in turn
    (the slow SINGLE_ROUND methods only in the first), so that a machine whose speed
    drifts (shared cores, steal time) slows every method alike and the ratios hold.
    repeats: timed passes per measurement (default `_repeats`). memory_limit_gib: dense
    runs whose (P, N) tensors would need more are skipped. threads: torch CPU threads in
    the workers (0: torch's default). in_process: measure in this process instead of a
    fresh one per measurement (smoke tests; memory then includes earlier measurements'
    leftovers). Returns the list of result dicts.
    """
    for w in workloads:
        if w not in WORKLOADS:
            raise ValueError(f"workloads: unknown workload {w!r}; expected some of {tuple(WORKLOADS)}")
    for m in methods:
        if m not in METHODS:
            raise ValueError(f"methods: unknown method {m!r}; expected some of {METHODS}")
    if rounds < 1:
        raise ValueError(f"rounds: expected at least 1, got {rounds}")
    results = []
    for w in workloads:
        runs = {m: [] for m in methods}
        skipped = {m: _skip_reason(m, w, memory_limit_gib, device) for m in methods}
        for k in range(rounds):
            for m in methods:
                if skipped[m] is not None or (k > 0 and m in SINGLE_ROUND):
                    continue
                r = measure(m, w, repeats or _repeats(m, w), device, threads, in_process)
                if "skipped" in r:
                    skipped[m] = r["skipped"]
                    continue
                runs[m].append(r)
                echo(json.dumps({key: v for key, v in r.items() if key != "times"} | {"round": k + 1}))
        for m in methods:
            if skipped[m] is not None:
                results.append({"method": m, "workload": w, "skipped": skipped[m]})
            else:
                results.append(_merge(runs[m]))
    text = "\n\n".join([
        device_section(SECTION, device),
        f"Forward + backward (loss = <image, v> + <alpha, v'>, gradients of means, quats, scales, "
        f"opacities, colours) of one {device.upper()} float32 render. Each workload runs in {rounds} "
        f"rounds of fresh processes, one per method in turn (dense and reference in the first only), "
        f"each with one warm-up and a few timed passes; the time is the median over all timed "
        f"passes, so that drift in the machine's speed (shared cores) slows every method alike. "
        f"Memory: the resident-set high-water mark (VmHWM) during the timed passes, absolute and "
        f"above the resident size before them (interpreter, torch and the scene excluded; freed "
        f"heap memory trimmed first; on CUDA the allocator's peak above its allocation before "
        f"them), median over the rounds. Scenes: `velogauss.bench.raster.make_scene` (seed 0; "
        f"screen-space standard deviations 0.2-2 px per axis, opacities 0.1-0.9). Ratios are to "
        f"the default backend (what `rasterize(backend=\"auto\")` picks here: "
        f"{default_method(device)}).",
        f"Machine: {machine(device)}.",
        f"Regenerate: `{_command(workloads, methods, device, threads, rounds)}`",
        _table(results, workloads, methods, device),
    ])
    write_section(out_path, device_section(SECTION, device), text)
    return results


if __name__ == "__main__":  # `measure`'s fresh interpreter: `_worker`'s arguments in, its result out, as JSON
    print(json.dumps(_worker(**json.loads(sys.argv[1]))))
