"""What simulating only the effects a scene calls for saves: the motion cost of one training
iteration under different effect profiles, measured side by side in one run.

Scene: the synthetic `multi` scene (three moving bodies over a static ground; its declared
effects are translation, rotation and static), represented by Gaussians at `n_points`
surface samples at t = 0 (no rendering is needed: only the motion is timed). Motion
parameters: `init_motion_params` with every zero-initialised head (time network, ADF,
acceleration) given small random values, so that every path computes real numbers.

Per configuration, float32 on the CPU, median of `repeats` passes after a warm-up:
- motion: `VeloGaussModel.state_at(t)` forward + backward (to every parameter), averaged
  over t = 0.25, 0.5, 0.75 (RK2, h = 0.05: the training defaults);
- physics: the residuals of VG-TRANSPORT (and VG-DIV when the motion is incompressible)
  at 1024 collocation points, forward + backward.
Configurations:
- every effect: what a model that assumes nothing builds (12 basis columns, acceleration on
  all 12, divergence), every particle integrated;
- the scene's effects: the declared ones (6 columns), every particle integrated;
- + static particles frozen: the same with the particles of the static ground marked as not
  moving, as static-particle detection (velogauss.train.static) finds them once trained
  (here taken from the ground truth, so the measurement does not depend on a training run);
- static scene: a scene declaring only `static` builds no motion at all.

Regenerate: velogauss bench effects
"""

import dataclasses
import statistics

import numpy as np
import torch

from velogauss.bench.harness import machine, regenerate_command, timed_passes, write_section
from velogauss.config import load_config
from velogauss.model import build_model, scene_spec
from velogauss.model.motion import motion_residuals
from velogauss.scenes import SCENES

SECTION = "## Effect profiles: cost of motion per iteration"
COMMAND = "velogauss bench effects"
TIMES = (0.25, 0.5, 0.75)
N_COLLOCATION = 1024
_HEAD_NOISE = 0.05


def build(effects, incompressible, points, colors, seed=0):
    """A model of the default config with the given effects (heads perturbed)."""
    cfg = load_config()
    # One pattern form: only the columns differ.
    cfg = dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, effects=tuple(effects),
                                                             incompressible=incompressible, patterns="mlp"))
    model = build_model(cfg, scene_spec(cfg, None), points, colors, np.random.default_rng(seed))
    if model.motion is not None:
        gen = torch.Generator().manual_seed(seed)
        with torch.no_grad():
            for p in model.motion.parameters():
                if not p.any():  # a zero-initialised head
                    p.add_(_HEAD_NOISE * torch.randn(p.shape, generator=gen))
    return model


def time_motion(model, repeats):
    """Median seconds of state_at forward + backward, averaged over TIMES."""
    params = [p for p in model.parameters() if p.requires_grad]

    def once():
        for t in TIMES:
            means, quats, scales, _ = model.state_at(t)
            loss = means.sum() + quats.sum() + scales.sum()
            if loss.requires_grad:
                torch.autograd.grad(loss, [p for p in params if p.requires_grad], allow_unused=True)

    once()
    return statistics.median(timed_passes(once, repeats)) / len(TIMES)


def time_physics(model, bounds, repeats, seed=0):
    """Median seconds of the physics residuals forward + backward (0 without motion)."""
    if model.motion is None:
        return 0.0
    rng = np.random.default_rng(seed)
    x = torch.as_tensor(rng.uniform(bounds[0], bounds[1], (N_COLLOCATION, 3)), dtype=torch.float32)
    params = list(model.motion.parameters())

    def once():
        r, div = motion_residuals(model.motion.params(), model.spec, x, 0.5)
        loss = r.square().mean() + (div.square().mean() if div is not None else 0.0)
        torch.autograd.grad(loss, params, allow_unused=True)

    once()
    return statistics.median(timed_passes(once, repeats))


def run(out_path="benchmarks/RESULTS.md", device="cpu", n_points=5000, repeats=5, threads=1, quick=False):
    """Measure every configuration and write the RESULTS.md section; return the rows."""
    if device != "cpu":
        raise ValueError(f"device: this benchmark runs on the CPU only, got {device!r}")
    if threads:
        torch.set_num_threads(threads)
    if quick:
        n_points, repeats = 400, 1
    scene = SCENES["multi"]()
    points, colors, _ = scene.sample_surface(n_points, np.random.default_rng(0))
    ground = [k for k, b in enumerate(scene.bodies) if b.name == "ground"][0]
    on_ground = scene.body_index(points, 0.0, margin=np.inf) == ground
    bounds = scene.bounds()
    configs = [
        ("every effect", ("translation", "rotation", "gravity", "stretch", "shear"), True, None),
        ("the scene's effects", tuple(scene.effects), scene.incompressible, None),
        ("the scene's effects + static particles frozen", tuple(scene.effects), scene.incompressible, ~on_ground),
        ("static scene (effects: static)", ("static",), True, None),
    ]
    rows = []
    for name, effects, incompressible, moving in configs:
        model = build(effects, incompressible, points, colors)
        spec = model.spec
        if moving is not None:
            model.set_moving(torch.as_tensor(moving))
        motion = time_motion(model, repeats)
        physics = time_physics(model, bounds, repeats)
        rows.append({"config": name, "columns": sum(spec.mask), "acc_columns": sum(spec.acc_mask),
                     "divergence": spec.divergence, "moving": int(model.moving.sum()) if spec.moving else 0,
                     "n": len(model.gaussians), "motion_s": motion, "physics_s": physics})
    _write(out_path, rows, n_points, repeats, quick, threads)
    return rows


def _write(out_path, rows, n_points, repeats, quick, threads):
    base = rows[0]["motion_s"] + rows[0]["physics_s"]
    lines = ["| configuration | velocity columns | acceleration columns | divergence loss | integrated particles "
             "| motion fwd+bwd (ms) | physics fwd+bwd (ms) | total (ms) | speed-up vs every effect |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        total = r["motion_s"] + r["physics_s"]
        speedup = f"{base / total:.1f}×" if total > 0 else "no motion computed"
        lines.append(f"| {r['config']} | {r['columns']} | {r['acc_columns']} | {'yes' if r['divergence'] else 'no'} "
                     f"| {r['moving']:,} of {r['n']:,} | {1e3 * r['motion_s']:.1f} | {1e3 * r['physics_s']:.1f} "
                     f"| {1e3 * total:.1f} | {speedup} |")
    command = regenerate_command(COMMAND, quick=quick, threads=threads)
    text = "\n\n".join([
        SECTION,
        f"The motion part of one training iteration on the `multi` scene ({n_points:,} Gaussians on its surfaces: "
        "three moving bodies over a static ground), under four effect profiles, measured side by side in one run "
        f"(`velogauss.bench.effects`; median of {repeats} passes, float32). Motion: `state_at(t)` forward + "
        "backward averaged over t = 0.25, 0.5, 0.75 (RK2, h = 0.05). Physics: the transport (and divergence) "
        f"residuals at {N_COLLOCATION} collocation points, forward + backward. The static particles are the "
        "ground's, taken from the ground truth as static-particle detection finds them on a trained model.",
        f"Machine: {machine()}.",
        f"Regenerate: `{command}`",
        "\n".join(lines),
    ])
    write_section(out_path, SECTION, text)
