"""VeloGauss: canonical Gaussians moved by the motion model, rendered at any time.

The model holds the canonical `Gaussians`, the `MotionParameters` (None for a static
scene) and the resolved `MotionSpec`; the motion itself is the pure function
`velogauss.model.motion.gaussians_at` (paper eqs. 5-6, spec VG-TRAJ, VG-ADF,
VG-ADF-COMPOSE). Only the particles flagged `moving` are integrated and deformed; the
others are rendered at their canonical state, so the cost of motion grows with the moving
part of the scene. Under scheme "adf-step" (VG-CARRY) the ADF's state at a start time is
carried to t by the velocity instead. Under `spec.future = "fit"` the model may hold a forecast:
a velocity-only motion fitted to its own trained paths (velogauss.train.forecast), which carries the
Gaussians past the window from their state at `spec.max_time` (spec/motion.md, "The future past the
window").

The model is a door of the fast path (spec/conventions.md, "Bad input"): the times and
points its public methods take from outside are checked here, finiteness included; what it
hands to `velogauss_fast` inside is then checked for shape only.
"""

import torch
from torch import nn

from velogauss.model import motion as motion_fns
from velogauss_core.motion import MotionSpec
from velogauss_fast.checks import check_array, check_finite
from velogauss_fast.motion.between import mixing_between
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.scalars import check_time
from velogauss_fast.quaternion import normalize_quat
from velogauss_core.rendering import RasterizeMode, check_mode
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.raster import rasterize


class VeloGaussModel(nn.Module):
    """The model that `velogauss train` learns and `eval`, `render`, `export` use.

    gaussians: `Gaussians`; motion: `MotionParameters` or None (static scene); spec: the
    `MotionSpec` both were built from; rasterize_mode: how its renders composite
    (velogauss_core.rendering, the config's `model.rasterize_mode`).
    """

    def __init__(self, gaussians, motion, spec: MotionSpec, rasterize_mode: RasterizeMode):
        super().__init__()
        check_mode(rasterize_mode)
        self.rasterize_mode = rasterize_mode
        if (motion is not None) != spec.moving:
            raise ValueError(f"motion: expected {'MotionParameters' if spec.moving else 'None'} for this spec")
        self.gaussians = gaussians
        self.motion = motion
        self.spec = spec
        self.forecast = None
        self.register_buffer("moving", torch.ones(len(gaussians), dtype=torch.bool))

    @property
    def has_velocity(self) -> bool:
        """A velocity field moves the particles (not for static scenes or deform-only)."""
        return self.spec.velocity is not None

    @property
    def sh_degree(self) -> int:
        return self.gaussians.sh_degree

    def motion_params(self) -> dict | None:
        """The motion parameter dict (`MotionParameters.params`), None for a static scene."""
        return None if self.motion is None else self.motion.params()

    def state_at(self, t, params: dict | None = None, spec: MotionSpec | None = None, offset: float = 0.0):
        """(means (N, 3), quats (N, 4) unit, scales (N, 3), base means x* (N, 3)) at time t.

        params: the motion parameter dict, when the caller already built it this step;
        spec: a variant of the model's spec (training skips the ADF before it learns), which
        never reads the forecast; past the window the model's own spec hands a held forecast the
        state at max_time (`set_forecast`);
        offset: scheme "adf-step" only, the signed step its training draws (VG-CARRY).
        A non-finite or non-scalar t raises ValueError.
        """
        _check_time(t)
        spec = self.spec if spec is None else spec
        g = self.gaussians
        if spec.moving and params is None:
            params = self.motion.params()
        if self._forecasts(t, spec):
            return self._forecast_state(params, t)
        return moving_state_at(params, spec, g.means, g.quats, g.scales, self.moving, t, offset)

    def set_forecast(self, forecast):
        """Hold `forecast` (velogauss.model.motion.MotionParameters of a velocity-only spec, or None)
        as the motion past the window; needs spec.future "fit"."""
        if forecast is not None and self.spec.future != "fit":
            raise ValueError(f"forecast: the model's spec.future is {self.spec.future!r}, not \"fit\"")
        self.forecast = forecast

    def _forecasts(self, t, spec):
        """Whether time t is the forecast's: past the window of the model's own spec, with a forecast held."""
        return self.forecast is not None and spec is self.spec and float(t) > spec.max_time

    def _forecast_state(self, params, t):
        """`state_at(t)` past the window under the forecast: the moving Gaussians' state at max_time
        integrated to t in the forecast's field (VG-STEP from max_time), their codes at their
        positions at t = 0, where the forecast's fit read them (spec/motion.md, "The future past
        the window")."""
        spec, g, T = self.spec, self.gaussians, self.spec.max_time
        x, q, s, xs = moving_state_at(params, spec, g.means, g.quats, g.scales, self.moving, T)
        start = moving_state_at(params, spec, g.means, g.quats, g.scales, self.moving, 0.0)[0]
        idx = torch.nonzero(self.moving).squeeze(1)
        fparams, fspec = self.forecast.params(), self.forecast.spec
        z = physics_code(fparams, start.index_select(0, idx), fspec)
        xi = x.index_select(0, idx)
        xf, qf, sf = base_state(fparams, xi, q.index_select(0, idx), s.index_select(0, idx), z, float(t),
                                fspec.step, fspec.integrator, fspec, t0=T)
        moved = xs.index_select(0, idx) + (xf - xi)
        return x.index_copy(0, idx, xf), q.index_copy(0, idx, qf), s.index_copy(0, idx, sf), xs.index_copy(0, idx, moved)

    def render_inputs_at(self, t):
        """The Gaussians at time t with their appearance, as a dict: means, quats, scales,
        opacities (N,), colors (N, (D+1)^2, 3) SH coefficients, sh_degree and rasterize_mode
        (what export and the renderer take)."""
        means, quats, scales, _ = self.state_at(t)
        return self.with_appearance(means, quats, scales)

    def with_appearance(self, means, quats, scales):
        """The `render_inputs_at` dict for a given geometry (N, 3), (N, 4), (N, 3)."""
        g = self.gaussians
        return {"means": means, "quats": quats, "scales": scales, "opacities": g.opacities, "colors": g.sh,
                "sh_degree": g.sh_degree, "rasterize_mode": self.rasterize_mode}

    def render(self, camera, t, background, spec: MotionSpec | None = None):
        """Render `camera` (velogauss.data.Camera) at time t over `background (3,)`:
        (image (H, W, 3), alpha (H, W, 1), meta) as `velogauss_fast.rasterize` returns them.
        spec: as in `state_at`."""
        means, quats, scales, _ = self.state_at(t, spec=spec)
        return render_gaussians(self.with_appearance(means, quats, scales), camera, background)

    def tracked_positions(self, t):
        """Positions (N, 3) whose paths the trajectory metric and figure follow: the physics
        positions x*(t) when a velocity field moves the particles, else (deform-only, static)
        the rendered means, the only motion such a model has."""
        means, _, _, base = self.state_at(t)
        return base if self.has_velocity else means

    def velocity_at(self, x, t):
        """Learned Eulerian velocity (M, 3) at world points x (M, 3); zero without a velocity model.
        Under spec.query_code "gaussians" the mixing weights at x are those of the Gaussians
        nearest to x at time t (their physics positions x*(t)), VG-FIELD-GAUSS; else the code
        network's at x (VG-FIELD). Past the window under a forecast, the forecast's field, its code
        read at x. A non-finite or wrongly shaped x, or a bad t, raises ValueError."""
        check_finite(x=check_array("x", x, (None, 3)))
        _check_time(t)
        if not self.has_velocity:
            return torch.zeros_like(x)
        if self._forecasts(t, self.spec):
            return motion_fns.velocity_at(self.forecast.params(), self.forecast.spec, x, t)
        params = self.motion.params()
        if self.spec.query_code == "gaussians":
            m = self._mixing_between(params, x, self.state_at(t, params)[3])
            return motion_fns.velocity_with_mixing(params, self.spec, x, t, m)
        return motion_fns.velocity_at(params, self.spec, x, t)

    def particle_velocity(self, x0, x, t):
        """Velocity (M, 3) the model gives the material points that started at x0 (M, 3) when
        they are at x (M, 3) at time t; zero without a velocity model. Under spec.query_code
        "gaussians" a point's mixing weights are those of the Gaussians nearest to x0 among the
        canonical means, frozen along its path (VG-FIELD-GAUSS); else the code network's at x0
        (`velogauss.model.motion.particle_velocity`). Past the window under a forecast, the
        forecast's field, its code read at x0. Non-finite or wrongly shaped points, or a bad t,
        raise ValueError."""
        check_array("x0", x0, (None, 3))
        check_finite(x0=x0, x=check_array("x", x, tuple(x0.shape)))
        _check_time(t)
        if not self.has_velocity:
            return torch.zeros_like(x)
        if self._forecasts(t, self.spec):
            return motion_fns.particle_velocity(self.forecast.params(), self.forecast.spec, x0, x, t)
        params = self.motion.params()
        if self.spec.query_code == "gaussians":
            m = self._mixing_between(params, x0, self.gaussians.means)
            return motion_fns.velocity_with_mixing(params, self.spec, x, t, m)
        return motion_fns.particle_velocity(params, self.spec, x0, x, t)

    def _mixing_between(self, params, x, centres):
        """VG-FIELD-GAUSS's mixing weights (M, K) at x (M, 3) from the Gaussians at `centres`
        (N, 3): their own weights, the rows of static (frozen) Gaussians zero, as they do not move."""
        own = motion_fns.own_mixing(params, self.spec, self.gaussians.means)
        return mixing_between(x, centres, own * self.moving[:, None].to(own.dtype))

    def set_moving(self, moving):
        """Flag which particles are integrated (bool (N,))."""
        self.moving = moving.to(device=self.moving.device, dtype=torch.bool)


def moving_state_at(params: dict | None, spec: MotionSpec, x0, quats, s0, moving, t, offset: float = 0.0,
                    adf=None):
    """(means (N, 3), quats (N, 4) unit, scales (N, 3), base means x* (N, 3)) at time t of the
    Gaussians whose canonical state is x0 (N, 3), quats (N, 4) (any norm), s0 (N, 3) > 0,
    the motion moving those flagged in `moving` (N,) bool and the others left canonical.

    `VeloGaussModel.state_at` without the model (the auxiliary losses' worker has its tensors,
    not the model: velogauss.train.aux_losses), t checked by the caller; params: the motion
    parameter dict, unread when nothing moves; offset: as `state_at`'s; adf: how the ADF's
    residual is evaluated (`velogauss.model.motion.gaussians_at`).
    """
    q0 = normalize_quat(quats)
    if not spec.moving or not bool(moving.any()):
        return x0, q0, s0, x0
    idx = torch.nonzero(moving).squeeze(1)
    x, q, s, xs = motion_fns.gaussians_at(params, spec, x0.index_select(0, idx), q0.index_select(0, idx),
                                          s0.index_select(0, idx), t, offset, adf)
    return x0.index_copy(0, idx, x), q0.index_copy(0, idx, q), s0.index_copy(0, idx, s), x0.index_copy(0, idx, xs)


def _check_time(t):
    """Raise ValueError unless t is a finite real number or a finite 0-d float tensor: a
    number costs nothing to test, a tensor one device sync, once per call of the model."""
    check_time("t", t)
    if isinstance(t, torch.Tensor):
        check_finite(t=t)


def render_gaussians(g, camera, background):
    """Rasterize a `VeloGaussModel.render_inputs_at` dict `g` from `camera` over `background (3,)`."""
    ref = g["means"]
    viewmat = torch.as_tensor(camera.viewmat, dtype=ref.dtype, device=ref.device)
    K = torch.as_tensor(camera.K, dtype=ref.dtype, device=ref.device)
    bg = torch.as_tensor(background, dtype=ref.dtype, device=ref.device)
    return rasterize(g["means"], g["quats"], g["scales"], g["opacities"], g["colors"], viewmat, K,
                     camera.width, camera.height, background=bg, sh_degree=g["sh_degree"], mode=g["rasterize_mode"])
