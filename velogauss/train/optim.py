"""Adam with 3DGS-style parameter groups and learning-rate schedules, and the optimiser
surgery that densification needs.

Groups: one per Gaussian field (means, log_scales, quats, opacity_logits, sh_dc, sh_rest),
one for the motion networks and one, named "acc", for the arrays that hold physical
quantities directly: the acceleration Q (VG-ACC), the rigid motion patterns B (VG-COEF-RIGID:
spins and centres) and the oscillators' coefficients C (VG-COEF-HARM; their shared frequency
stays with the networks). These get their own, larger rate: Adam moves a parameter by about
its rate per step, Q's entries must reach |v|²/L (a spin of 4 rad per unit time has
centripetal coefficients of 16) and B's are spins and world positions of order 1, where a
network's weights stay O(1) and its width scales its output. Means, motion and acc decay
exponentially from their initial to their final rate (3DGS's `get_expon_lr_func` without delay); means scale with the
camera extent, as in 3DGS. The motion and acc rates run their decay from the end of the warm-up.
Over the last `train.acc_cooldown` of the iterations the acc rate falls a further
`lr_acc_final / lr_acc_cooled` (10x): the patterns' world quantities stop wandering by a
fraction of a pixel per step before training ends.
"""

import math

import torch

from velogauss.model.gaussians import FIELDS

# Adam's epsilon of 3DGS: 1e-15, so the tiny gradients of far-away Gaussians still move them.
ADAM_EPS = 1e-15


def make_optimizer(model, train_cfg, extent):
    """Adam over the model's parameters with the groups of the module docstring."""
    t = train_cfg
    lrs = {"means": t.lr_means * extent, "log_scales": t.lr_scales, "quats": t.lr_quats,
           "opacity_logits": t.lr_opacity, "sh_dc": t.lr_sh, "sh_rest": t.lr_sh / 20.0}
    groups = [{"params": [getattr(model.gaussians, name)], "lr": lrs[name], "name": name} for name in FIELDS]
    if model.motion is not None:
        acc = acceleration_group(model.motion)
        networks = [p for p in model.motion.parameters() if all(p is not a for a in acc)]
        groups.append({"params": networks, "lr": t.lr_motion, "name": "motion"})
        if acc:
            groups.append({"params": acc, "lr": t.lr_acc, "name": "acc"})
    # foreach: one call per step for all the tensors, not a dozen Python-level ops per tensor.
    return torch.optim.Adam(groups, lr=0.0, eps=ADAM_EPS, foreach=True)


def acceleration_group(motion):
    """The parameters of `motion` (velogauss.model.motion.MotionParameters) trained at the
    acceleration's larger rate: Q, rigid patterns' spins and knots, oscillators' coefficients."""
    spec = motion.spec
    acc = [motion.acc] if spec.acceleration else []
    if spec.rigid_patterns:
        acc.append(motion.time)
    if spec.velocity == "affine" and spec.pattern_form == "harmonic":
        # C, not the frequency (VG-COEF-HARM): Adam moves a parameter by about its rate
        # per step whatever its gradient, and the shared frequency, started where the
        # video oscillates, is barely determined while the curriculum's window is shorter
        # than a period, so at the larger rate it drifts.
        acc.append(motion.time[0])
    return acc


def set_learning_rates(optimizer, iteration, train_cfg, extent):
    """Means, motion and acc rates at `iteration` (log-linear decay to the final values; the
    acc rate then cools down over the last `train.acc_cooldown` of the iterations)."""
    t = train_cfg
    progress = min(1.0, iteration / max(1, t.iterations))
    motion_progress = min(1.0, max(0, iteration - t.warmup) / max(1, t.iterations - t.warmup))
    for group in optimizer.param_groups:
        if group["name"] == "means":
            group["lr"] = _log_lerp(t.lr_means * extent, t.lr_means_final * extent, progress)
        elif group["name"] == "motion":
            group["lr"] = _log_lerp(t.lr_motion, t.lr_motion_final, motion_progress)
        elif group["name"] == "acc":
            group["lr"] = _log_lerp(t.lr_acc, t.lr_acc_final, motion_progress) * _cooldown(iteration, t)


def update_gaussian_groups(optimizer, gaussians, keep, new_rows):
    """Keep the rows `keep` (bool (N,)) of every Gaussian field, append `new_rows`, and carry
    Adam's moments along (zero for the new rows), so optimisation continues seamlessly.

    new_rows: dict field -> (M, ...) tensor. Updates `gaussians` in place.
    """
    tensors = {}
    for group in optimizer.param_groups:
        name = group["name"]
        if name not in FIELDS:
            continue
        old = group["params"][0]
        tensors[name] = torch.cat([old.detach()[keep], new_rows[name].detach()])
    gaussians.set_tensors(tensors)
    for group in optimizer.param_groups:
        name = group["name"]
        if name not in FIELDS:
            continue
        old = group["params"][0]
        new = getattr(gaussians, name)
        state = optimizer.state.pop(old, None)
        if state:
            extra = new_rows[name].shape[0]
            for key in ("exp_avg", "exp_avg_sq"):
                moment = state[key][keep]
                state[key] = torch.cat([moment, moment.new_zeros((extra,) + moment.shape[1:])])
            optimizer.state[new] = state
        group["params"][0] = new


def _cooldown(iteration, t):
    """The acc rate's factor at `iteration`: 1 before the last `t.acc_cooldown` of the
    iterations, then log-linearly down to `t.lr_acc_cooled / t.lr_acc_final` at the last one."""
    span = t.acc_cooldown * t.iterations
    if span <= 0:
        return 1.0
    progress = min(1.0, max(0.0, (iteration - (t.iterations - span)) / span))
    return _log_lerp(1.0, t.lr_acc_cooled / t.lr_acc_final, progress)


def _log_lerp(start, end, progress):
    return math.exp((1.0 - progress) * math.log(start) + progress * math.log(end))
