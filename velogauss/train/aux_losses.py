"""The auxiliary losses of a training step: those no render goes through, computed beside the renders.

VG-LOSS-PHYS (the physics residuals), VG-LOSS-CARRY and VG-LOSS-MIX (the mixing weights'
entropy) read the motion parameters and detached canonical Gaussians only: nothing of the
renders' graph reaches them, and their gradients reach the motion parameters only. A step
therefore

1. draws their random numbers first, in the main thread and always in the same order
   (`draw`), so a run's draws never depend on timing and a resumed run repeats them;
2. computes them and their gradients (`loss_and_gradients`, torch.autograd.grad onto the
   motion parameters) in a worker process while the main thread renders (`start`;
   velogauss.train.aux_worker);
3. adds those gradients to the renders' after its own backward (`finish`), always
   in that order: the numbers depend neither on which finishes first nor on whether
   a worker ran at all (one thread, `--threads 1` or OMP_NUM_THREADS=1: the same function
   runs inline).

The auxiliary losses read the motion parameters and the detached canonical Gaussians
(`Canonical`), not the model: that is all the worker process is sent.

Why a worker helps on a CPU with two cores: the auxiliary losses are a large share of a step's
work (the profile in benchmarks/RESULTS.md). The worker waits on a socket, not in an OpenMP barrier, so
beside another process it takes no core that it does not use (velogauss/threads.py).

Collocation points near the Gaussians (placement "gaussians") are drawn as indices into the
moving Gaussians plus offsets. Only the drawn Gaussians are moved to the collocation time:
each Gaussian's motion reads its own canonical state alone, so the subset's rows equal the
whole batch's up to float32 rounding, at `n_points` Gaussians' cost instead of every one's
(benchmarks/RESULTS.md, "Training step profile at real resolution").
"""

from typing import NamedTuple

import numpy as np
import torch

from velogauss.model.velogauss_model import moving_state_at
from velogauss.model.motion import carry_loss, motion_residuals
from velogauss.train.sampling import collocation_points, collocation_time, draw_near
from velogauss_fast.losses import mixing_entropy_loss, physics_loss
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import mixing_logits


class PhysicsDraw(NamedTuple):
    """VG-LOSS-PHYS's draws: the ramp factor, the collocation time, and either the box points
    x (n, 3) (index None) or, near the Gaussians, `index` (n,) into the model's Gaussians and
    `offsets` (n, 3)."""

    ramp: float
    t: float
    x: torch.Tensor | None
    index: torch.Tensor | None
    offsets: torch.Tensor | None


class CarryDraw(NamedTuple):
    """VG-LOSS-CARRY's draws: the times t_a -> t and the Gaussians `index` (M,)."""

    t_a: float
    t: float
    index: torch.Tensor


class Canonical(NamedTuple):
    """What the auxiliary losses read of the model: its canonical Gaussians, detached, means (N, 3),
    quats (N, 4) (raw, any norm), scales (N, 3) > 0, and which of them move, moving (N,) bool."""

    means: torch.Tensor
    quats: torch.Tensor
    scales: torch.Tensor
    moving: torch.Tensor


def canonical(model):
    """The `Canonical` of a VeloGaussModel `model`."""
    g = model.gaussians
    return Canonical(g.means.detach(), g.quats.detach(), g.scales.detach(), model.moving)


def motion_leaves(motion):
    """The motion parameters (velogauss.model.motion.MotionParameters) the auxiliary losses
    differentiate: those that train this step, in the module's order."""
    return [p for p in motion.parameters() if p.requires_grad]


class Draws(NamedTuple):
    """What `loss_and_gradients` needs besides the model: each loss's draws, None when it is off."""

    physics: PhysicsDraw | None
    carry: CarryDraw | None
    mixing: torch.Tensor | None  # indices (M,) of the Gaussians whose mixing weights are scored

    @property
    def any(self):
        return any(d is not None for d in self)


def draw(cfg, model, spec, it, rng, bounds, window, device):
    """The auxiliary losses' draws of iteration `it`, in the order the losses are summed:
    physics, carry, mixing. cfg: the run's Config; model: the VeloGaussModel; spec: the step's
    MotionSpec; rng: the run's NumPy Generator; bounds: the scene's box (lo (3,), hi (3,));
    window: the latest time the curriculum draws at `it` (FrameSampler.window); device: where
    the drawn tensors go."""
    motion_on = spec.moving and it >= cfg.train.warmup
    physics = carry = mixing = None
    if motion_on and spec.physics_loss:
        p = cfg.physics
        ramp = min(1.0, (it - cfg.train.warmup + 1) / max(1, p.ramp))
        if p.placement == "gaussians" and bool(model.moving.any()):  # else the box: nothing to be near
            t = collocation_time(rng)
            moving = torch.nonzero(model.moving).squeeze(1)
            lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
            index, offsets = draw_near(len(moving), p.n_points, p.jitter * float(np.linalg.norm(hi - lo)), rng,
                                       model.gaussians.means.dtype, device)
            physics = PhysicsDraw(ramp, t, None, moving.index_select(0, index), offsets)
        else:
            x, t = collocation_points(bounds, p.bounds_margin, p.n_points, rng, torch.float32, device)
            physics = PhysicsDraw(ramp, t, x, None, None)
    if motion_on and spec.carry_loss and cfg.train.lambda_carry > 0:
        t = float(rng.uniform(0.0, window))
        t_a = float(np.clip(t + rng.uniform(-cfg.train.carry_horizon, cfg.train.carry_horizon), 0.0, window))
        carry = CarryDraw(t_a, t, draw_moving(model, cfg.train.carry_points, rng))
    if motion_on and spec.velocity == "affine" and cfg.train.lambda_mix > 0:
        mixing = draw_moving(model, cfg.train.mix_points, rng)
    return Draws(physics, carry, mixing)


def draw_moving(model, count, rng):
    """Indices (M,) of `count` of `model`'s moving Gaussians drawn without replacement, or all
    of them when there are no more."""
    idx = torch.nonzero(model.moving).squeeze(1)
    if len(idx) > count:
        idx = idx[torch.as_tensor(rng.choice(len(idx), count, replace=False), device=idx.device)]
    return idx


def loss_and_gradients(canon, leaves, cfg, params, spec, draws):
    """(loss (0-d, detached), [(motion parameter, its gradient or None)]) of the drawn
    auxiliary losses: ramp · VG-LOSS-PHYS + lambda_carry · VG-LOSS-CARRY + VG-LOSS-MIX (the mixing
    weight is inside `mixing_entropy_loss`). canon: the model's `Canonical`; leaves: the
    motion parameters to differentiate (`motion_leaves`); `params`: the step's motion
    parameter dict, built from them."""
    loss = 0.0
    if draws.physics is not None:
        d, p = draws.physics, cfg.physics
        x = d.x if d.index is None else collocation_near(canon, d, params, spec)
        r, div = motion_residuals(params, spec, x, d.t)
        loss = loss + physics_loss(r, div, d.ramp * p.lambda_transport, d.ramp * p.lambda_div)
    if draws.carry is not None:
        d = draws.carry
        x0, q0, s0 = (v.index_select(0, d.index) for v in (canon.means, canon.quats, canon.scales))
        loss = loss + cfg.train.lambda_carry * carry_loss(params, spec, x0, q0, s0, d.t_a, d.t)
    if draws.mixing is not None:
        # Detached means: the entropy shapes the code and mixing networks, it does not move the Gaussians.
        z = physics_code(params, canon.means.index_select(0, draws.mixing), spec)
        loss = loss + mixing_entropy_loss(mixing_logits(params, z), cfg.train.lambda_mix)
    return loss.detach(), list(zip(leaves, torch.autograd.grad(loss, leaves, allow_unused=True)))


@torch.no_grad()
def collocation_near(canon, draw, params, spec):
    """x (n, 3): the collocation points of `draw` (a PhysicsDraw near the Gaussians), the
    drawn Gaussians' means at draw.t plus the offsets (only the drawn Gaussians are moved, each
    once: see the module docstring); canon: the model's `Canonical`."""
    drawn, rows = torch.unique(draw.index, return_inverse=True)
    means = moving_state_at(params, spec, *(v.index_select(0, drawn) for v in canon), draw.t)[0]
    return means.index_select(0, rows) + draw.offsets


def start(model, cfg, params, spec, draws, worker):
    """Start the auxiliary losses of `draws` (`loss_and_gradients`): a pending result for
    `finish`, or None when nothing was drawn. In `worker` (a velogauss.train.aux_worker.AuxWorker,
    when the run's thread budget allows two parallel parts: velogauss.train.loop.prepare), else
    inline when it is None."""
    if not draws.any:
        return None
    if worker is not None:
        return worker.submit(model.motion, canonical(model), cfg, spec, draws)
    return _Done(loss_and_gradients(canonical(model), motion_leaves(model.motion), cfg, params, spec, draws))


def finish(pending):
    """Wait for `start`'s auxiliary losses and add their gradients to the motion parameters' (the
    renders' backward has run); returns their loss as a float, 0.0 when none ran. Re-raises
    what the auxiliary losses raised."""
    if pending is None:
        return 0.0
    loss, grads = pending.result()
    for leaf, grad in grads:
        if grad is not None:
            leaf.grad = grad if leaf.grad is None else leaf.grad + grad
    return float(loss)


class _Done(NamedTuple):
    """The auxiliary losses computed inline: `start`'s pending result, already there."""

    value: tuple

    def result(self):
        return self.value
