"""What each training iteration looks at: a training frame, and physics collocation points.

Frames follow a time curriculum: during the warm-up only the earliest frames (the canonical
state) are drawn: those at t = 0, or, with `warmup_views` > 1 where t = 0 has fewer frames than
an iteration renders (monocular video), the earliest `warmup_views` frames within
`WARMUP_WINDOW_SHARE` of the window, so that the canonical Gaussians are seen from several
cameras. Then the window of allowed times opens linearly to `max_time` over `curriculum`
iterations, so the velocity is learned from short integrations first.
A scene without motion draws from every frame at once. An iteration may look at several
training views of its frame's time (`train.views`): the Gaussians' state is computed once
and seen by several cameras, which pins positions in depth, where one view's gradient is
blind. Collocation points (VG-TRANSPORT, VG-DIV) lie near the moving Gaussians at their
time (`physics.placement = "gaussians"`) or uniform over the scene box grown by a margin
("box"), at one uniform time in [0, 1] per iteration: the future is constrained too.
"""

import numpy as np
import torch

from velogauss.config import SCHEDULE_ITERATIONS
from velogauss_core.constants import WARMUP_WINDOW_SHARE


class FrameSampler:
    """Draws training frame indices by the curriculum of the module docstring.

    times: (F,) frame times; warmup, curriculum: iterations; moving: the scene has motion;
    views: the frames an iteration renders (`train.views`); warmup_views: the frames the warm-up
    draws from where t = 0 has fewer than `views` (`train.warmup_views`).
    """

    def __init__(self, times, warmup, curriculum, moving, views=1, warmup_views=1):
        self.times = np.asarray(times, dtype=np.float64)
        self.warmup, self.curriculum, self.moving = int(warmup), int(curriculum), bool(moving)
        self.t0 = float(self.times.min())
        self.t1 = float(self.times.max())
        self.t_warm = warmup_end(self.times, views, warmup_views)

    def window(self, iteration):
        """Latest time that may be drawn at `iteration`."""
        if not self.moving:
            return self.t1
        if iteration < self.warmup:
            return self.t_warm
        opened = min(1.0, (iteration - self.warmup + 1) / max(1, self.curriculum))
        return max(self.t_warm, self.t0 + opened * (self.t1 - self.t0))

    def sample(self, iteration, rng):
        """One frame index allowed at `iteration`, uniformly among the allowed frames."""
        allowed = np.flatnonzero(self.times <= self.window(iteration) + 1e-9)
        return int(allowed[rng.integers(len(allowed))])

    def sample_views(self, iteration, rng, views):
        """Up to `views` frame indices of one time: `sample`'s frame first, then other frames
        of exactly its time (other cameras), drawn without replacement. A static scene's
        frames all show the one state, so any frames go together."""
        first = self.sample(iteration, rng)
        same = self.times == self.times[first] if self.moving else np.ones(len(self.times), dtype=bool)
        others = np.flatnonzero(same & (np.arange(len(self.times)) != first))
        extra = rng.choice(others, size=min(views - 1, len(others)), replace=False) if views > 1 else []
        return [first, *(int(i) for i in extra)]


def warmup_end(times, views, warmup_views):
    """The latest time the warm-up draws (spec/density.md, "The warm-up's views"), from the
    frames' `times` (F,): their start where `views` or more frames lie there (a rig: an
    iteration finds its views at t = 0, as the schedule was tuned), else the time of the
    `warmup_views`-th earliest frame, but no later than WARMUP_WINDOW_SHARE of the window past
    the start (monocular video)."""
    times = np.sort(np.asarray(times, dtype=np.float64))
    t0, t1 = float(times[0]), float(times[-1])
    if np.count_nonzero(times == t0) >= views:
        return t0
    nth = float(times[min(int(warmup_views), len(times)) - 1])
    return max(t0, min(nth, t0 + WARMUP_WINDOW_SHARE * (t1 - t0)))


def views_per_iteration(times, views, moving=True):
    """The mean number of frames `FrameSampler.sample_views` returns for `views` over the
    training frames' `times` (F,): each frame is drawn as often, with up to `views` - 1 others
    of exactly its time (any others when the scene does not move)."""
    times = np.asarray(times, dtype=np.float64)
    if not moving:
        return float(min(views, len(times)))
    _, inverse, counts = np.unique(times, return_inverse=True, return_counts=True)
    return float(np.minimum(views, counts[inverse]).mean())


def auto_iterations(times, views, moving=True):
    """`train.iterations = "auto"`: SCHEDULE_ITERATIONS x `views` / `views_per_iteration`,
    rounded: as many rendered training views as a run of SCHEDULE_ITERATIONS that finds every
    view it asks for. A scene filmed by `views` or more cameras at each time keeps
    SCHEDULE_ITERATIONS; monocular video (one camera per time, as D-NeRF's) gets `views` times
    as many iterations (spec/density.md, "The iteration budget")."""
    return max(1, round(SCHEDULE_ITERATIONS * views / views_per_iteration(times, views, moving)))


def collocation_points(bounds, margin, n_points, rng, dtype, device):
    """(x (n_points, 3) uniform in `bounds (2, 3)` grown by `margin` of its size per side,
    t = `collocation_time(rng)`), drawn in that order."""
    lo, hi = np.asarray(bounds[0], dtype=np.float64), np.asarray(bounds[1], dtype=np.float64)
    pad = margin * (hi - lo)
    x = rng.uniform(lo - pad, hi + pad, size=(n_points, 3))
    return torch.as_tensor(x, dtype=dtype, device=device), collocation_time(rng)


def collocation_time(rng):
    """The collocation time of an iteration, uniform in [0, 1]: the future is constrained too."""
    return float(rng.uniform(0.0, 1.0))


def draw_near(count, n_points, jitter, rng, dtype, device):
    """(index (n_points,) int64 into `count` >= 1 points, drawn with replacement; offsets
    (n_points, 3) of `dtype`, isotropic normal of standard deviation `jitter` (world units)).
    Placement "gaussians" of VG-LOSS-PHYS: the collocation points are the drawn Gaussians'
    means at the collocation time plus the offsets, so the residual binds where the particles
    are, not in the empty corners of the box."""
    index = torch.as_tensor(rng.integers(0, count, size=n_points), device=device)
    offsets = torch.as_tensor(rng.standard_normal((n_points, 3)) * jitter, dtype=dtype, device=device)
    return index, offsets


def camera_extent(cameras):
    """3DGS's scene scale: 1.1 times the largest distance of a camera centre from their mean."""
    centres = np.stack([c.centre for c in cameras])
    radius = np.linalg.norm(centres - centres.mean(axis=0), axis=1).max()
    # A single camera (or coincident ones) has no spread: fall back to its distance from the origin.
    return 1.1 * float(radius if radius > 0 else np.linalg.norm(centres[0]) or 1.0)
