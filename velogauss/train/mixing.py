"""Patterns that start apart: the mixing weights fitted to a spatial partition before training.

VG-COEF mixes K motion patterns with weights m(z) = softmax(z A + c) of the physics code
z = E(γ(x0)). At initialisation every pattern is the same (a still scene) and the weights
are nearly uniform (the largest is ~1/K), so the gradient of each pattern is nearly the
mean over all particles: the patterns move together, and the difference between two bodies
is a small-eigenvalue direction that Adam crawls along: bodies that move differently, or a
body beside the still ground, are learned slowly (benchmarks/FIDELITY.md, section 0b).

`separate_patterns` (config `model.mixing_init = "clusters"`) partitions the initial
points into K clusters (k-means) and fits the code network and the mixing layer so that each
point puts MIXING_INIT_WEIGHT on its cluster's pattern and the rest evenly on the others.
Each pattern then starts as the motion of one region of the scene; a region's motion gets
the gradient of its own pixels, and particles still move between patterns as training
finds the bodies (spec/motion.md, VG-COEF, "Initialisation").

The regions are not bodies: one body is cut into several, each of which must learn the
body's whole motion from its own pixels. That is what a scene of several motions needs and a
scene of one body pays for, hence "auto" (`resolve_mixing_init`). In
training, the mixing entropy (VG-LOSS-MIX) then makes each particle commit to one of the
patterns it started near, so the regions of one body settle on one motion.
"""

import numpy as np
import torch
from scipy.cluster.vq import kmeans2

from velogauss_core.constants import MIXING_INIT_LR, MIXING_INIT_STEPS, MIXING_INIT_WEIGHT
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import mixing_weights


def resolve_mixing_init(choice, spec):
    """"clusters" or "uniform" for the config's `model.mixing_init` and a `MotionSpec`:
    "auto" is "clusters" when the spec's effects hold `static` (a still body beside moving
    ones: more than one motion to tell apart) and something moves, else "uniform"."""
    if choice != "auto":
        return choice
    return "clusters" if spec.moving and "static" in spec.effects else "uniform"


def cluster_targets(points, k, rng):
    """(labels (N,) int in [0, k), centres (k, 3)): k-means of points (N, 3) NumPy, seeded by rng.

    k-means++ seeding; fewer points than clusters, or duplicates, leave some clusters empty,
    which is harmless (their patterns keep the uniform share)."""
    seed = int(rng.integers(2**31 - 1))
    centres, labels = kmeans2(np.asarray(points, dtype=np.float64), k, minit="++", seed=seed)
    return labels, centres


def place_patterns(motion, points, rng, mixing, centres):
    """Start `motion`'s patterns (in place) on the initial points (N, 3) tensor.

    Under mixing "clusters" one k-means partition into K regions (`cluster_targets`) serves
    both: the mixing weights are fitted to it (`separate_patterns`), and with centres
    "clusters" each pattern is written about its region's centroid (VG-COEF-CENTRE), so that
    pattern k turns its region about the region's middle. Under mixing "uniform" the patterns
    start as one body, and with centres "clusters" every pattern is written about the points'
    mean. Centres "origin" leave the world's origin, as do rigid patterns, which carry centres
    of their own.
    """
    if motion.spec.pattern_form == "rigid":
        centres = "origin"
    if mixing == "clusters":
        labels, centroids = cluster_targets(points.detach().cpu().numpy(), motion.spec.n_patterns, rng)
        separate_patterns(motion, points, rng, labels=labels)
    else:
        centroids = points.detach().double().mean(0, keepdim=True).cpu().numpy()
    if centres == "clusters":
        with torch.no_grad():
            motion.centre.copy_(torch.as_tensor(centroids, dtype=motion.centre.dtype).expand_as(motion.centre))


def separate_patterns(motion, points, rng, steps=MIXING_INIT_STEPS, weight=MIXING_INIT_WEIGHT, labels=None):
    """Fit `motion`'s code network and mixing layer (in place) so that m(E(γ(x))) puts
    `weight` on the pattern of x's k-means cluster, for the points (N, 3) (a tensor), or on
    pattern `labels[i]` (N,) ints in [0, K) when given (the backtest's clusters of paths).

    Cross-entropy against the smoothed one-hot targets, full batch, `steps` Adam steps at
    MIXING_INIT_LR. Returns the mean weight on the own cluster's pattern after the fit."""
    spec = motion.spec
    k = spec.n_patterns
    x = points.detach().to(motion.code[0].dtype)
    if labels is None:
        labels, _ = cluster_targets(x.cpu().numpy(), k, rng)
    labels = torch.as_tensor(labels, dtype=torch.long, device=x.device)
    # The cross-entropy against these targets is smallest exactly at m = targets.
    targets = torch.full((len(x), k), (1.0 - weight) / (k - 1), dtype=x.dtype, device=x.device)
    targets[torch.arange(len(x), device=x.device), labels] = weight
    trained = [*motion.code.parameters(), *motion.mix.parameters()]
    optimizer = torch.optim.Adam(trained, lr=MIXING_INIT_LR)
    for _ in range(steps):
        params = motion.params()
        log_m = torch.log(mixing_weights(params, physics_code(params, x, spec)))
        loss = -(targets * log_m).sum(1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    with torch.no_grad():
        params = motion.params()
        m = mixing_weights(params, physics_code(params, x, spec))
        return float(m[torch.arange(len(x), device=x.device), labels].mean())
