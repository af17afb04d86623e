"""Frames per second of `velogauss view` on the CPU: what one browser frame costs.

Model: the default config on the default scene (`toss`), represented by `n_points` Gaussians
at surface samples at t = 0, every zero-initialised motion head given small random values
(`velogauss.bench.effects.build`), so the ADF and the integration compute real numbers.
A frame is what a viewer's render thread does: `FrameRenderer.render` (numba rasterizer,
under torch.no_grad) + `annotate` + the JPEG encoding viser sends, at `size`² pixels, from a
camera on the scene's camera ring (distance 4, looking at the centre). Three kinds of frame,
measured in interleaved rounds so that machine drift hits all alike:

- orbit: a new camera every frame at a fixed time (the Gaussians at that time are kept);
- orbit, moving: the same at half the resolution, what the viewer sends while the camera moves;
- play: a new time every frame (motion integrated from t = 0, then rasterized).

Reported: the median over rounds of each kind's frames per second (wall clock), with the
machine's load average before and after (the wall-clock numbers are only as quiet as the
machine was), and the process's CPU time per frame (summed over its threads), which other
work on the machine inflates far less: 1 / (CPU time per frame) is the frame rate the
process reaches on one core of its own, a lower bound for what it reaches on two.
Regenerate: velogauss bench viewer
"""

import os
import statistics
import time

import numpy as np

from velogauss.bench.harness import machine, regenerate_command, write_section
from velogauss.threads import apply_threads

SECTION = "## Viewer frames per second (CPU)"
COMMAND = "velogauss bench viewer"
JPEG_QUALITY = 85  # as velogauss.view.server sends


def setup(n_points, seed=0):
    """`(renderer, scene)`: a `FrameRenderer` of the perturbed default model on `toss`."""
    from velogauss.bench.effects import build
    from velogauss.scenes import SCENES
    from velogauss.view.frame import FrameRenderer

    scene = SCENES["toss"]()
    points, colors, _ = scene.sample_surface(n_points, np.random.default_rng(seed))
    model = build(tuple(scene.effects), scene.incompressible, points, colors, seed)
    return FrameRenderer(model, (1.0, 1.0, 1.0)), scene


def ring_camera(angle, size, centre):
    """A `size`² camera at distance 4 on the ring around `centre`, 20° above it."""
    from velogauss.data.cameras import Camera, intrinsics_from_fov, look_at
    from velogauss.scenes.writer import DNERF_CAMERA_ANGLE_X

    elevation = np.radians(20.0)
    eye = centre + 4.0 * np.array([np.cos(angle) * np.cos(elevation), np.sin(angle) * np.cos(elevation),
                                   np.sin(elevation)])
    return Camera(look_at(eye, centre), intrinsics_from_fov(DNERF_CAMERA_ANGLE_X, size, size), size, size)


def frame(renderer, camera, t, max_time):
    """One viewer frame: render, annotate, JPEG-encode as viser does; returns the bytes."""
    # viser's private encoder: the very encoding the viewer's frames go through (the one
    # private import tests/app/test_layers.py allows).
    from viser._scene_api import _encode_image_binary

    from velogauss.view.frame import annotate

    image = annotate(renderer.render(camera, t), t, max_time)
    return _encode_image_binary(image, "jpeg", JPEG_QUALITY)[1]


def run(out_path="benchmarks/RESULTS.md", device="cpu", n_points=10_000, size=256, frames=20, rounds=5, threads=0,
        quick=False):
    """Measure the three kinds of frame and write the RESULTS.md section; return the rows."""
    if device != "cpu":
        raise ValueError(f"device: this benchmark runs on the CPU only, got {device!r}")
    apply_threads(threads)  # what `velogauss view --threads` sets (0: velogauss's default)
    if quick:
        n_points, frames, rounds = 500, 2, 1
    load_before = os.getloadavg()
    renderer, scene = setup(n_points)
    centre = scene.bounds().mean(axis=0)
    max_time = 0.75
    kinds = {
        "orbit": lambda i: frame(renderer, ring_camera(0.05 * i, size, centre), 0.5, max_time),
        "orbit, moving (half resolution)": lambda i: frame(renderer, ring_camera(0.05 * i, size // 2, centre),
                                                          0.5, max_time),
        "play": lambda i: frame(renderer, ring_camera(0.0, size, centre), 0.05 + (0.9 * i / frames), max_time),
    }
    for render in kinds.values():  # warm-up: numba compilation, allocator
        render(0)
    fps = {name: [] for name in kinds}
    cpu = {name: [] for name in kinds}
    for _ in range(rounds):
        for name, render in kinds.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            for i in range(1, frames + 1):
                render(i)
            fps[name].append(frames / (time.perf_counter() - start))
            cpu[name].append((time.process_time() - start_cpu) / frames)
    rows = [{"kind": name, "fps": statistics.median(v), "min": min(v), "max": max(v),
             "cpu_s": statistics.median(cpu[name])} for name, v in fps.items()]
    _write(out_path, rows, n_points, len(renderer.model.gaussians), size, frames, rounds, threads, quick,
           load_before, os.getloadavg())
    return rows


def _write(out_path, rows, n_points, n_gaussians, size, frames, rounds, threads, quick, load_before, load_after):
    lines = ["| frame | pixels | frames/s (median, wall clock) | range over rounds | CPU ms per frame "
             "| 1 / CPU time (frames/s on one free core) |", "|---|---|---:|---:|---:|---:|"]
    for r in rows:
        pixels = f"{size // 2}²" if "half" in r["kind"] else f"{size}²"
        lines.append(f"| {r['kind']} | {pixels} | {r['fps']:.1f} | {r['min']:.1f}–{r['max']:.1f} "
                     f"| {1e3 * r['cpu_s']:.0f} | {1 / r['cpu_s']:.1f} |")
    options = [] if (n_points, size) == (10_000, 256) else [f"--points {n_points}", f"--size {size}"]
    text = "\n\n".join([
        SECTION,
        f"One frame of `velogauss view` ({n_gaussians:,} Gaussians of the default model on `toss`, numba "
        f"rasterizer, annotated and JPEG-encoded as sent to the browser), {frames} frames per kind in each of "
        f"{rounds} interleaved rounds (`velogauss.bench.viewer`). Orbit: a new camera at a fixed time; play: a "
        "new time every frame (motion integrated from t = 0).",
        f"Machine: {machine()}. Load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after "
        f"(the machine has {os.cpu_count()} cores; a load above that means other work shared them).",
        f"Regenerate: `{regenerate_command(COMMAND, *options, quick=quick, threads=threads)}`",
        "\n".join(lines),
    ])
    write_section(out_path, SECTION, text)
