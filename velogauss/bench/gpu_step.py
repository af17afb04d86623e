"""The dynamic training step against gsplat's static 3DGS step, at the same size (issue 38).

The default scene is rendered at `--size` px (5 cameras, 3 trained, 6 times; as
`velogauss bench step_profile --sizes`) with a point cloud of `--gaussians` points, and the
default training's `Trainer` is built on it on `--device`; from warmup + curriculum on (motion,
ADF and full physics loss on) its step and density control are timed per iteration, the device
synchronised around each. The static step is what 3DGS does with the same Gaussians, the
same three views and the same target images: `gsplat.rasterization` of the three cameras in one
batch (its fused projection, SH colours and tile compositing), an L1 loss, the backward and an
Adam step over the six Gaussian fields. No dynamic step can be cheaper, so the ratio of the two
is the motion's cost. The static step needs gsplat on a CUDA device; elsewhere its column reads
"gsplat not available" and only the dynamic step is timed.

Regenerate: velogauss bench gpu_step --device cuda
Smoke test: velogauss bench gpu_step --quick --out /tmp/bench.md
"""

import tempfile
from pathlib import Path

import torch

from velogauss.bench.harness import regenerate_command, timed_passes, write_table_section
from velogauss_fast.backends import gsplat_available

SECTION = "## The dynamic step against gsplat's static step"
COMMAND = "velogauss bench gpu_step"
SIZE, GAUSSIANS = 800, 100_000  # the comparison
QUICK_SIZE, QUICK_GAUSSIANS = 24, 200
WARMUP = 2  # the first passes compile kernels and grow allocator pools
ITERATIONS, QUICK_ITERATIONS = 10, 2


def _seconds(device, step, count):
    """Mean wall seconds of `count` calls of `step`, the device synchronised around each."""
    sync = torch.cuda.synchronize if torch.device(device).type == "cuda" else (lambda: None)

    def synced():
        step()
        sync()

    sync()
    return sum(timed_passes(synced, count)) / count


def static_step(loop):
    """A function running one static 3DGS step with gsplat on `loop`'s canonical Gaussians (copied:
    the dynamic model is not touched) and its first training time's three views: render, L1, backward, Adam."""
    from gsplat import rasterization

    g, device = loop.model.gaussians, loop.device
    params = {name: t.detach().clone().requires_grad_(True) for name, t in g.tensors().items()}
    optimizer = torch.optim.Adam([{"params": [p], "lr": 1e-3} for p in params.values()], eps=1e-15)
    frames = [f for f in loop.data.train if f.time == loop.data.train[0].time][: loop.cfg.train.views]
    viewmats = torch.stack([torch.as_tensor(f.camera.viewmat, dtype=torch.float32) for f in frames]).to(device)
    Ks = torch.stack([torch.as_tensor(f.camera.K, dtype=torch.float32) for f in frames]).to(device)
    targets = torch.stack([torch.as_tensor(f.image) for f in frames]).to(device)
    width, height = frames[0].camera.width, frames[0].camera.height

    def step():
        optimizer.zero_grad(set_to_none=True)
        colors = torch.cat([params["sh_dc"], params["sh_rest"]], dim=1)
        images, _, _ = rasterization(params["means"], params["quats"], torch.exp(params["log_scales"]),
                                     torch.sigmoid(params["opacity_logits"]), colors, viewmats, Ks, width, height,
                                     sh_degree=g.sh_degree)
        (images - targets).abs().mean().backward()
        optimizer.step()

    return step


def measure(size, gaussians, device, iterations, quick=False):
    """{"dynamic_s", "static_s" (None without gsplat), "gaussians", "views"}: mean seconds per step."""
    from velogauss.bench.load import make_default_scene, next_iterations, training_loop

    with tempfile.TemporaryDirectory(prefix="velogauss-gpu-step-") as tmp:
        scene = make_default_scene(Path(tmp) / "scene", quick, n_points=gaussians, resolution=size)
        loop, first = training_loop(scene, 0, device=device)
        static = static_step(loop) if gsplat_available(device) else None
        dynamic = next_iterations(loop, first)
        _seconds(device, dynamic, WARMUP)
        result = {"dynamic_s": _seconds(device, dynamic, iterations), "gaussians": len(loop.model.gaussians),
                  "views": loop.cfg.train.views, "static_s": None}
        if static is not None:
            _seconds(device, static, WARMUP)
            result["static_s"] = _seconds(device, static, iterations)
    return result


def run(out_path="benchmarks/RESULTS.md", device="cuda", size=None, gaussians=None, iterations=None, quick=False):
    """Time both steps and write the "## The dynamic step against gsplat's static step" section."""
    from velogauss.run import check_device

    check_device(device)
    size = size or (QUICK_SIZE if quick else SIZE)
    gaussians = gaussians or (QUICK_GAUSSIANS if quick else GAUSSIANS)
    iterations = iterations or (QUICK_ITERATIONS if quick else ITERATIONS)
    for name, value, least in (("--size", size, 16), ("--gaussians", gaussians, 16), ("--iterations", iterations, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise ValueError(f"{name}: expected a whole number of at least {least}, got {value!r}")
    result = measure(size, gaussians, device, iterations, quick)
    static = result["static_s"]
    ratio = "—" if static is None else f"{result['dynamic_s'] / static:.2f}"
    lines = ["| size | Gaussians | views per step | dynamic step (ms) | gsplat's static step (ms) | dynamic / static |",
             "|---:|---:|---:|---:|---:|---:|",
             f"| {size} px | {result['gaussians']:,} | {result['views']} | {1e3 * result['dynamic_s']:.1f} | "
             f"{'gsplat not available' if static is None else f'{1e3 * static:.1f}'} | {ratio} |"]
    options = [] if (size, gaussians) == ((QUICK_SIZE, QUICK_GAUSSIANS) if quick else (SIZE, GAUSSIANS)) else [
        f"--size {size}", f"--gaussians {gaussians}"]
    if iterations != (QUICK_ITERATIONS if quick else ITERATIONS):
        options.append(f"--iterations {iterations}")
    if device != "cuda":  # this command's default device
        options.append(f"--device {device}")
    write_table_section(out_path, SECTION, [
        "The default training's step (motion, ADF and full physics loss on, density control) on the default "
        f"scene rendered at {size} px from a {gaussians:,}-point cloud, against gsplat's static 3DGS step on "
        "the same Gaussians, views and images (`gsplat.rasterization` of the views in one batch, L1, backward, "
        f"Adam): mean of {iterations} steps after {WARMUP} to warm up, the device synchronised around each "
        "(velogauss.bench.gpu_step). The static step is the floor a dynamic step cannot beat.",
    ], regenerate_command(COMMAND, *options, quick=quick), lines, device=device)
    return result
