"""VeloGauss: canonical Gaussians moved by the motion model, rendered at any time.

At time t (paper eqs. 5-6, spec VG-TRAJ, VG-ADF, VG-ADF-COMPOSE):
  z = E(γ(x0));  (x*, q*, s*) = base_state(x0, q0, s0, z, t);
  (Δx, Δq, Δs) = ADF(x0, t_adf, z);  x = x* + Δx, q = q* ⊗ Δq, s = s* exp(Δs),
with t_adf = min(t, max_time) when `adf_clamp_time` (the ADF has never seen the future).
Only the particles flagged `moving` are integrated and deformed; the others are rendered at
their canonical state, so the cost of motion grows with the moving part of the scene.
Ablations: "no-adf" drops the ADF, "deform-only" drops the velocity (x* = x0: a
DefGS-style deformation model, its ADF evaluated at every t), and a static profile builds
no motion at all.
Scheme "adf-step" (scheme (b), VG-CARRY) replaces the first two
lines: the ADF's state at a start time is carried to t by the velocity.
"""

import torch
from torch import nn

from velogauss_fast.motion.deform import compose_state
from velogauss_fast.motion.trajectory import normalize_quat
from velogauss_fast.raster import rasterize
from velogauss_ref.motion.carry import carry_start


class VeloGaussModel(nn.Module):
    """The model that `velogauss train` learns and `eval`, `render`, `export` use.

    gaussians: `Gaussians`; motion: `MotionModel` or None (static scene); max_time: end of
    the observed window; adf_clamp_time: hold the ADF at max_time beyond it.
    """

    def __init__(self, gaussians, motion, max_time, adf_clamp_time=True, scheme="integrate"):
        super().__init__()
        self.gaussians = gaussians
        self.motion = motion
        self.max_time = float(max_time)
        self.adf_clamp_time = bool(adf_clamp_time)
        self.scheme = scheme  # velogauss.config.SCHEMES
        # Training switches the ADF off until it starts learning (velogauss.train.loop): its
        # last layer starts at zero, so skipping it is then exactly the identity, and cheaper.
        self.adf_enabled = True
        self.register_buffer("moving", torch.ones(len(gaussians), dtype=torch.bool))

    @property
    def has_velocity(self):
        """A velocity field moves the particles (not for static scenes or deform-only)."""
        return self.motion is not None and self.motion.velocity_kind is not None

    @property
    def sh_degree(self):
        return self.gaussians.sh_degree

    def state_at(self, t, offset=0.0):
        """(means (N, 3), quats (N, 4) unit, scales (N, 3), base means x* (N, 3)) at time t.

        offset: scheme "adf-step" only, the signed step its training draws (VG-CARRY); the
        base means are then the means.
        """
        g = self.gaussians
        x0, q0, s0 = g.means, normalize_quat(g.quats), g.scales
        if self.motion is None or not bool(self.moving.any()):
            return x0, q0, s0, x0
        idx = torch.nonzero(self.moving).squeeze(1)
        x0m, q0m, s0m = x0.index_select(0, idx), q0.index_select(0, idx), s0.index_select(0, idx)
        z = self.motion.codes(x0m)
        if self.scheme == "adf-step" and self.has_velocity and self.motion.use_adf and self.adf_enabled:
            x, q, s = self.motion.carried_state(x0m, q0m, s0m, z, t, carry_start(t, offset, self.max_time))
            return (x0.index_copy(0, idx, x), q0.index_copy(0, idx, q), s0.index_copy(0, idx, s),
                    x0.index_copy(0, idx, x))
        if self.has_velocity:
            xs, qs, ss = self.motion.base_state(x0m, q0m, s0m, z, t)
        else:
            xs, qs, ss = x0m, q0m, s0m
        x, q, s = xs, normalize_quat(qs), ss
        if self.motion.use_adf and self.adf_enabled:
            t_adf = min(float(t), self.max_time) if self.adf_clamp_time else t
            dx, dq, ds = self.motion.adf_residual(x0m, t_adf, z)
            x, q, s = compose_state(xs, qs, ss, dx, dq, ds)
        return (x0.index_copy(0, idx, x), q0.index_copy(0, idx, q), s0.index_copy(0, idx, s),
                x0.index_copy(0, idx, xs))

    def gaussians_at(self, t):
        """The Gaussians at time t as a dict: means, quats, scales, opacities (N,), colors
        (N, (D+1)^2, 3) SH coefficients and sh_degree (what export and the renderer take)."""
        means, quats, scales, _ = self.state_at(t)
        return self.with_appearance(means, quats, scales)

    def with_appearance(self, means, quats, scales):
        """The `gaussians_at` dict for a given geometry (N, 3), (N, 4), (N, 3)."""
        g = self.gaussians
        return {"means": means, "quats": quats, "scales": scales, "opacities": g.opacities, "colors": g.sh,
                "sh_degree": g.sh_degree}

    def render(self, camera, t, background):
        """Render `camera` (velogauss.data.Camera) at time t over `background (3,)`:
        (image (H, W, 3), alpha (H, W, 1), meta) as `velogauss_fast.rasterize` returns them."""
        return render_gaussians(self.gaussians_at(t), camera, background)

    def base_positions(self, t):
        """Physics-only positions x*(t) (N, 3) (VG-TRAJ, without the ADF)."""
        return self.state_at(t)[3]

    def tracked_positions(self, t):
        """Positions (N, 3) whose paths the trajectory metric and figure follow: the physics
        positions x*(t) when a velocity field moves the particles, else (deform-only, static)
        the rendered means, the only motion such a model has."""
        means, _, _, base = self.state_at(t)
        return base if self.has_velocity else means

    def velocity_at(self, x, t):
        """Learned Eulerian velocity (M, 3) at world points x (M, 3); zero without a velocity model."""
        if not self.has_velocity:
            return torch.zeros_like(x)
        return self.motion.velocity_at(x, t)

    def particle_velocity(self, x0, x, t):
        """Velocity (M, 3) the model gives the material points that started at x0 (M, 3) when
        they are at x (M, 3) at time t (`MotionModel.particle_velocity`); zero without a
        velocity model."""
        if not self.has_velocity:
            return torch.zeros_like(x)
        return self.motion.particle_velocity(x0, x, t)

    def set_moving(self, moving):
        """Flag which particles are integrated (bool (N,))."""
        self.moving = moving.to(device=self.moving.device, dtype=torch.bool)


def render_gaussians(g, camera, background):
    """Rasterize a `gaussians_at` dict `g` from `camera` over `background (3,)`."""
    ref = g["means"]
    viewmat = torch.as_tensor(camera.viewmat, dtype=ref.dtype, device=ref.device)
    K = torch.as_tensor(camera.K, dtype=ref.dtype, device=ref.device)
    bg = torch.as_tensor(background, dtype=ref.dtype, device=ref.device)
    return rasterize(g["means"], g["quats"], g["scales"], g["opacities"], g["colors"], viewmat, K,
                     camera.width, camera.height, background=bg, sh_degree=g["sh_degree"])
