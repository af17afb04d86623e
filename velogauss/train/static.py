"""Detect the particles that do not move over the observed window, so they are not integrated.

A particle's motion at time t is bounded by how far any point within one standard
deviation of it moves: |x(t) − x0| + s_max · angle(q(t), q0) + max |s(t) − s0|. A particle
whose bound stays below its threshold at every probe time in [0, max_time] is static: the
model renders it at its canonical state (`VeloGaussModel.moving`), skipping its
integration and ADF. Training sets the threshold per particle to `STATIC_MOTION_PX` pixels
at the particle's depth (`pixel_footprint`), so "static" means "no training image can see
it move", whatever the scene's units. Detection re-examines every particle, so one frozen
too early moves again at the next detection once the shared motion networks say it should.
"""

import numpy as np
import torch

from velogauss_core.constants import NEAR_PLANE
from velogauss_fast.quaternion import normalize_quat

# Probe times: the observed window [0, max_time] at this many evenly spaced points.
_PROBES = 5


def pixel_footprint(points, cameras):
    """World size (N,) of one pixel at `points (N, 3)` (tensor) in the camera that sees them
    largest: min over `cameras` (velogauss.data.Camera) of depth / focal length, over the
    cameras the point is in front of (depth > NEAR_PLANE); inf where it is behind them all."""
    best = torch.full((len(points),), float("inf"), dtype=points.dtype, device=points.device)
    for camera in cameras:
        view = torch.as_tensor(camera.viewmat[2], dtype=points.dtype, device=points.device)
        depth = points @ view[:3] + view[3]
        size = depth / float(np.max(camera.K[[0, 1], [0, 1]]))
        best = torch.where(depth > NEAR_PLANE, torch.minimum(best, size), best)
    return best


def detect_moving(model, max_time, threshold, spec=None):
    """bool (N,): particles whose motion bound exceeds `threshold` (world units: a number, or
    a tensor (N,) per particle) somewhere in [0, max_time], under `spec` (default the
    model's; see `VeloGaussModel.state_at`). Leaves `model.moving` unchanged."""
    g = model.gaussians
    saved = model.moving
    with torch.no_grad():
        model.set_moving(torch.ones_like(saved))
        x0, s0 = g.means, g.scales
        q0 = normalize_quat(g.quats)
        bound = torch.zeros(len(g), dtype=x0.dtype, device=x0.device)
        params = model.motion_params()
        for t in torch.linspace(0.0, max_time, _PROBES).tolist():
            x, q, s, _ = model.state_at(t, params, spec)
            angle = 2 * torch.acos((q * q0).sum(1).abs().clamp(max=1.0))
            step = (x - x0).norm(dim=1) + s0.max(dim=1).values * angle + (s - s0).abs().max(dim=1).values
            bound = torch.maximum(bound, step)
        model.set_moving(saved)
    return bound > threshold
