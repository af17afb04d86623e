"""Adaptive density control of 3DGS: clone, split, prune, opacity reset.

Statistics: after every rendered view, each Gaussian that was visible adds the norm of the
loss gradient of its screen-space mean, in NDC units (pixel gradient times half the image
size, as 3DGS and gsplat measure it). Every `densify.every` iterations in
[`densify.start`, `densify.until`]:
- clone the Gaussians whose mean gradient reaches `grad_threshold` and whose largest
  scale is at most `percent_dense` of the camera extent (under-reconstruction);
- split those above that size into two, sampled from the Gaussian, scales / 1.6;
- prune the Gaussians with opacity below `prune_opacity`, and, after the first opacity
  reset, those larger than a tenth of the extent in the world or, on screen, with a radius
  above `screen_radius_limit` (3DGS's 20 px, growing with the image past 128 px).
The count never exceeds `max_gaussians` (under `cap_schedule` "linear", its share of it so
far, `cap_at`): candidates are taken by decreasing gradient.
Every `opacity_reset_every` iterations opacities are clamped to at most 0.01, so that
floaters must earn their opacity back (3DGS).
"""

import math

import numpy as np
import torch

from velogauss.train.optim import update_gaussian_groups
from velogauss_core.constants import MAX_SCREEN_RADIUS_PX, MAX_SCREEN_RADIUS_SHARE
from velogauss_fast.quaternion import quat_to_rotmat

# 3DGS's split: two children, each scale divided by 0.8 * 2.
_SPLIT_CHILDREN = 2
_SPLIT_SCALE_DIVISOR = 1.6
# 3DGS's limit on a Gaussian's size in the world, for pruning once opacities have been reset.
_MAX_WORLD_SCALE_FRACTION = 0.1
_RESET_OPACITY = 0.01


class DensityStats:
    """Per-Gaussian accumulators: summed NDC gradient norms, view counts, largest radius."""

    def __init__(self, n, device="cpu"):
        self.reset(n, device)

    def reset(self, n, device="cpu"):
        """Zero the accumulators for n Gaussians."""
        self.grad = torch.zeros(n, device=device)
        self.count = torch.zeros(n, device=device)
        self.max_radius = torch.zeros(n, device=device)

    def add(self, mean2d_grad, radius, valid, width, height):
        """Accumulate one view: mean2d_grad (N, 2) pixel gradients, radius (N,), valid (N,)."""
        scale = mean2d_grad.new_tensor([0.5 * width, 0.5 * height])
        norm = (mean2d_grad * scale).norm(dim=1)
        self.grad += torch.where(valid, norm, torch.zeros_like(norm))
        self.count += valid.to(self.count.dtype)
        self.max_radius = torch.maximum(self.max_radius, torch.where(valid, radius.to(self.max_radius.dtype), 0.0))

    def state_dict(self):
        return {"grad": self.grad, "count": self.count, "max_radius": self.max_radius}

    def load_state_dict(self, state):
        self.grad, self.count, self.max_radius = state["grad"], state["count"], state["max_radius"]


def densify_and_prune(model, optimizer, stats, cfg, extent, image_size, after_reset, generator, done):
    """One round of clone/split/prune (see the module docstring); resets `stats`.

    cfg: `DensifyConfig`; extent: camera extent (world units); image_size: the training
    images' larger side in pixels (the screen-size pruning's scale); after_reset: an opacity reset
    has happened (enables the size pruning); generator: torch.Generator for the split samples;
    done: the iterations done (the cap's share under cfg.cap_schedule "linear", `cap_at`).
    Returns {"cloned", "split", "pruned", "total"}.
    """
    g = model.gaussians
    n = len(g)
    with torch.no_grad():
        grads = stats.grad / stats.count.clamp(min=1)
        max_scale = g.scales.max(dim=1).values
        small = max_scale <= cfg.percent_dense * extent
        hot = grads >= cfg.grad_threshold
        clone = hot & small
        split = hot & ~small
        budget = max(0, cap_at(cfg, done) - n)
        clone, split = _within_budget(grads, clone, split, budget)

        prune = g.opacities < cfg.prune_opacity
        if after_reset:
            prune |= (stats.max_radius > screen_radius_limit(image_size)) | (max_scale > _MAX_WORLD_SCALE_FRACTION * extent)
        tensors = g.tensors()
        cloned = {name: t[clone] for name, t in tensors.items()}
        children = _split_children(g, split, generator)
        new_rows = {name: torch.cat([cloned[name], children[name]]) for name in tensors}
        # Split parents are replaced by their children; pruned Gaussians go.
        keep = ~(prune | split)
        n_new = len(new_rows["means"])
        moving = torch.cat([model.moving[keep], torch.ones(n_new, dtype=torch.bool, device=model.moving.device)])
        update_gaussian_groups(optimizer, g, keep, new_rows)
        model.set_moving(moving)
        stats.reset(len(g), device=stats.grad.device)
    return {"cloned": int(clone.sum()), "split": int(split.sum()), "pruned": int((prune & ~split).sum()),
            "total": len(g)}


def screen_radius_limit(image_size):
    """The screen radius (px) past which a Gaussian is pruned after an opacity reset, for images
    whose larger side is `image_size` px: max(MAX_SCREEN_RADIUS_PX, MAX_SCREEN_RADIUS_SHARE x
    image_size), 3DGS's 20 px up to 128 px and a share of the image above (spec/density.md)."""
    return max(MAX_SCREEN_RADIUS_PX, MAX_SCREEN_RADIUS_SHARE * image_size)


def cap_at(cfg, done):
    """The most Gaussians a densification round after `done` iterations may leave: max_gaussians,
    or under cap_schedule "linear" its share (done - start) / (until - start) of it."""
    if cfg.cap_schedule == "fixed":
        return cfg.max_gaussians
    return int(cfg.max_gaussians * min(1.0, max(0.0, (done - cfg.start) / max(1, cfg.until - cfg.start))))


def reset_opacity(model, optimizer):
    """Clamp every opacity to at most 0.01 and forget its Adam moments (3DGS)."""
    g = model.gaussians
    with torch.no_grad():
        cap = math.log(_RESET_OPACITY / (1 - _RESET_OPACITY))
        g.opacity_logits.clamp_(max=cap)
    state = optimizer.state.get(g.opacity_logits)
    if state:
        state["exp_avg"].zero_()
        state["exp_avg_sq"].zero_()


def _within_budget(grads, clone, split, budget):
    """Keep the highest-gradient candidates so that clones + extra split children <= budget."""
    cost = clone.to(torch.int64) + split.to(torch.int64) * (_SPLIT_CHILDREN - 1)
    if int(cost.sum()) <= budget:
        return clone, split
    order = torch.argsort(torch.where(clone | split, grads, torch.full_like(grads, -1.0)), descending=True)
    allowed = torch.zeros_like(clone)
    within = torch.cumsum(cost[order], 0) <= budget
    allowed[order[within]] = True
    return clone & allowed, split & allowed


def _split_children(g, split, generator):
    """Two children per split Gaussian: means sampled from it, scales divided by 1.6."""
    tensors = g.tensors()
    parents = {name: t[split].repeat_interleave(_SPLIT_CHILDREN, dim=0) for name, t in tensors.items()}
    scales = torch.exp(parents["log_scales"])
    # The generator lives on the CPU (torch_generator), so a CUDA run draws the same noise.
    noise = torch.randn(scales.shape, generator=generator, dtype=scales.dtype).to(scales.device)
    R = quat_to_rotmat(parents["quats"])
    parents["means"] = parents["means"] + (R @ (scales * noise)[..., None])[..., 0]
    parents["log_scales"] = torch.log(scales / _SPLIT_SCALE_DIVISOR)
    return parents


def torch_generator(rng):
    """A torch.Generator seeded from the NumPy Generator `rng` (so one seed drives both)."""
    return torch.Generator().manual_seed(int(rng.integers(np.iinfo(np.int64).max)))
