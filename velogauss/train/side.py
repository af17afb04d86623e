"""The losses of a training step that no render goes through, computed beside the renders.

VG-LOSS-PHYS, VG-LOSS-CARRY and VG-LOSS-MIX read the motion parameters and detached
canonical Gaussians only: nothing of the renders' graph reaches them, and their gradients
reach the motion parameters only. A step therefore

1. draws their random numbers first, in the main thread and always in the same order
   (`draw`), so a run's draws never depend on timing and a resumed run repeats them;
2. computes them and their gradients (`side_loss`, torch.autograd.grad onto the motion
   parameters) in a worker thread while the main thread renders (`start`);
3. adds those gradients to the renders' after its own backward (`finish`), always
   in that order: the numbers depend neither on which thread finishes first nor on whether
   a worker ran at all (one thread, `--threads 1` or OMP_NUM_THREADS=1: the same function
   runs inline).

Why a thread helps on a 2-core CPU: torch releases the GIL inside each kernel, and the side
losses are a quarter of a step's work (the profile in benchmarks/RESULTS.md). A worker thread
waits on a lock, not in an OpenMP barrier, so beside another process it takes no core that
it does not use (velogauss/threads.py).

Collocation points near the Gaussians (placement "gaussians") are drawn as indices into the
moving Gaussians plus offsets. Every moving Gaussian is moved to the collocation time, not
only the drawn ones: a batch of another size rounds differently in float32, and those
roundings, grown over a training, changed the default scene's results by several dB
(benchmarks/RESULTS.md, "Toward a 2x step"); moving all of them keeps the training the one
the losses computed after the renders would give, to the last bit.
"""

import concurrent.futures
import functools
from typing import NamedTuple

import numpy as np
import torch

from velogauss.model.motion import carry_loss, motion_residuals
from velogauss.train.sampling import collocation_points, draw_near
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


class Draws(NamedTuple):
    """What `side_loss` needs besides the model: each loss's draws, None when it is off."""

    physics: PhysicsDraw | None
    carry: CarryDraw | None
    mixing: torch.Tensor | None  # indices (M,) of the Gaussians whose mixing weights are scored

    @property
    def any(self):
        return any(d is not None for d in self)


def draw(loop, it, spec):
    """The side losses' draws of iteration `it` (velogauss.train.loop._Loop `loop`, the spec
    of the step), in the order the losses are summed: physics, carry, mixing."""
    cfg, model = loop.cfg, loop.model
    motion_on = spec.moving and it >= cfg.train.warmup
    physics = carry = mixing = None
    if motion_on and spec.physics_loss:
        p = cfg.physics
        ramp = min(1.0, (it - cfg.train.warmup + 1) / max(1, p.ramp))
        # Drawn under either placement: it gives t, and the box points drawn first keep every
        # recorded run's random stream (near the Gaussians they are then not used).
        x, t = collocation_points(loop.data.bounds, p.bounds_margin, p.n_points, loop.rng, torch.float32, loop.device)
        physics = PhysicsDraw(ramp, t, x, None, None)
        if p.placement == "gaussians" and bool(model.moving.any()):  # else the box: nothing to be near
            moving = torch.nonzero(model.moving).squeeze(1)
            lo, hi = (np.asarray(b, dtype=np.float64) for b in loop.data.bounds)
            index, offsets = draw_near(len(moving), p.n_points, p.jitter * float(np.linalg.norm(hi - lo)), loop.rng,
                                       model.gaussians.means.dtype, loop.device)
            physics = PhysicsDraw(ramp, t, None, moving.index_select(0, index), offsets)
    if motion_on and spec.carry_loss and cfg.train.lambda_carry > 0:
        window = loop.sampler.window(it)
        t = float(loop.rng.uniform(0.0, window))
        t_a = float(np.clip(t + loop.rng.uniform(-cfg.train.carry_horizon, cfg.train.carry_horizon), 0.0, window))
        carry = CarryDraw(t_a, t, draw_moving(model, cfg.train.carry_points, loop.rng))
    if motion_on and spec.velocity == "affine" and cfg.train.lambda_mix > 0:
        mixing = draw_moving(model, cfg.train.mix_points, loop.rng)
    return Draws(physics, carry, mixing)


def draw_moving(model, count, rng):
    """Indices (M,) of `count` of `model`'s moving Gaussians drawn without replacement, or all
    of them when there are no more."""
    idx = torch.nonzero(model.moving).squeeze(1)
    if len(idx) > count:
        idx = idx[torch.as_tensor(rng.choice(len(idx), count, replace=False), device=idx.device)]
    return idx


def side_loss(model, cfg, params, spec, draws):
    """(loss (0-d, detached), [(motion parameter, its gradient or None)]) of the drawn side
    losses: ramp · VG-LOSS-PHYS + lambda_carry · VG-LOSS-CARRY + VG-LOSS-MIX (the mixing
    weight is inside `mixing_entropy_loss`). `params`: the step's motion parameter dict."""
    loss = 0.0
    g = model.gaussians
    if draws.physics is not None:
        d, p = draws.physics, cfg.physics
        x = d.x if d.index is None else collocation_near(model, d, params, spec)
        r, div = motion_residuals(params, spec, x, d.t)
        loss = loss + physics_loss(r, div, d.ramp * p.lambda_transport, d.ramp * p.lambda_div)
    if draws.carry is not None:
        d = draws.carry
        x0, q0, s0 = (v.detach().index_select(0, d.index) for v in (g.means, g.quats, g.scales))
        loss = loss + cfg.train.lambda_carry * carry_loss(params, spec, x0, q0, s0, d.t_a, d.t)
    if draws.mixing is not None:
        # Detached means: the entropy shapes the code and mixing networks, it does not move the Gaussians.
        z = physics_code(params, g.means.detach().index_select(0, draws.mixing), model.motion.spec.config)
        loss = loss + mixing_entropy_loss(mixing_logits(params, z), cfg.train.lambda_mix)
    leaves = [p for p in model.motion.parameters() if p.requires_grad]
    return loss.detach(), list(zip(leaves, torch.autograd.grad(loss, leaves, allow_unused=True)))


@torch.no_grad()
def collocation_near(model, draw, params, spec):
    """x (n, 3): the collocation points of `draw` (a PhysicsDraw near the Gaussians), the
    drawn Gaussians' means at draw.t plus the offsets (every moving Gaussian is moved: see
    the module docstring)."""
    return model.state_at(draw.t, params, spec)[0].index_select(0, draw.index) + draw.offsets


def start(model, cfg, params, spec, draws, worker):
    """Start the side losses of `draws` (`side_loss`): a Future, or None when nothing was
    drawn. In the worker thread when `worker` (the run's thread budget allows two parallel
    parts: velogauss.train.loop.prepare), else inline."""
    if not draws.any:
        return None
    if worker:
        return _worker().submit(side_loss, model, cfg, params, spec, draws)
    done = concurrent.futures.Future()
    done.set_result(side_loss(model, cfg, params, spec, draws))
    return done


def finish(pending):
    """Wait for `start`'s side losses and add their gradients to the motion parameters' (the
    renders' backward has run); returns their loss as a float, 0.0 when none ran. Re-raises
    what the side losses raised."""
    if pending is None:
        return 0.0
    loss, grads = pending.result()
    for leaf, grad in grads:
        if grad is not None:
            leaf.grad = grad if leaf.grad is None else leaf.grad + grad
    return float(loss)


@functools.cache
def _worker():
    """The process's one side-loss thread (steps run one at a time)."""
    return concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="velogauss-side")
