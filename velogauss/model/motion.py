"""The motion model as a trainable module: physics code, velocity, acceleration, ADF.

Holds the motion parameter dict of spec/motion.md as parameters and evaluates it with
`velogauss_fast` (VG-CODE ... VG-DIV). What is built follows the scene's
`MotionProfile` and the ablation (paper Table "ablation"):

- velocity "affine" (PDS on): Φ(x) w(t, z) over the profile's basis columns, with the
  VG-ROTSCALE rule moving rotations and scales; "mlp" (PDS off, "no-pds"): an
  unconstrained MLP v(γ(x), t) that moves positions only (the paper's replacement),
  integrated the same way; None ("deform-only"): no velocity at all.
- the acceleration polynomial Q only when the profile accelerates;
- the ADF network only when the ablation keeps it.
"""

import torch
from torch import nn
from torch.func import jvp

from velogauss.config import INTEGRATORS
from velogauss_fast.motion.carry import carried_state, carry_loss
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.motion.integrate import integrate
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.coefficients import coefficients
from velogauss_fast.motion.velocity import velocity, velocity_field
from velogauss_fast.nn import mlp, positional_encoding
from velogauss_fast.physics.acceleration import acceleration_field
from velogauss_fast.physics.residuals import physics_residuals, transport_residual
from velogauss_ref.constants import ACC_POLY_DEGREE
from velogauss_ref.motion.config import MotionConfig, init_motion_params, mlp_layers


VELOCITY_KINDS = ("affine", "mlp", None)


class MotionModel(nn.Module):
    """Velocity, acceleration and auxiliary deformation of one scene (see the module docstring).

    motion_cfg: `MotionConfig` (sizes and the profile's masks); profile: `MotionProfile`;
    velocity: one of VELOCITY_KINDS; adf: build the ADF; integrator in INTEGRATORS and
    step > 0 (VG-INTEG); rng: NumPy Generator for the initial weights (`init_motion_params`).
    """

    def __init__(self, motion_cfg, profile, velocity, adf, integrator, step, rng):
        super().__init__()
        if velocity not in VELOCITY_KINDS:
            raise ValueError(f"velocity: expected one of {VELOCITY_KINDS}, got {velocity!r}")
        if integrator not in INTEGRATORS:
            raise ValueError(f"integrator: expected one of {INTEGRATORS}, got {integrator!r}")
        self.cfg, self.profile = motion_cfg, profile
        self.velocity_kind, self.use_adf = velocity, bool(adf)
        self.integrator, self.step = integrator, float(step)
        params = init_motion_params(rng, motion_cfg)
        self.code = _parameter_list(params["code"])
        self.mix = _parameter_list(params["mix"])
        if velocity == "affine":
            self.time = _parameter_list(params["time"])
        elif velocity == "mlp":
            self.velocity_mlp = _parameter_list(_velocity_mlp_layers(rng, motion_cfg))
        if profile.acceleration:
            self.acc = nn.Parameter(torch.tensor(params["acc"], dtype=torch.float32))
        if self.use_adf:
            self.adf = _parameter_list(params["adf"])

    def params(self):
        """The spec's parameter dict; a scene without acceleration gets Q = 0 (a ≡ 0), not a parameter."""
        ref = self.code[0]
        acc = self.acc if self.profile.acceleration else ref.new_zeros(ACC_POLY_DEGREE + 1, self.cfg.n_patterns, 12)
        out = {"code": _layers(self.code), "mix": _layers(self.mix), "acc": acc}
        if self.pds:
            out["time"] = _layers(self.time)
        if self.use_adf:
            out["adf"] = _layers(self.adf)
        return out

    @property
    def pds(self):
        """The particle dynamics system (affine velocity) is on."""
        return self.velocity_kind == "affine"

    def codes(self, x0):
        """Physics codes z (N, L) of canonical positions x0 (N, 3) (VG-CODE)."""
        return physics_code(self.params(), x0, self.cfg)

    def base_state(self, x0, q0, s0, z, t):
        """(x*, q*, s*) at time t by integration from t = 0 (VG-TRAJ); shapes as x0, q0, s0.

        Without PDS only positions move (the MLP velocity has no rotation or strain rule).
        """
        if self.pds:
            return base_state(self.params(), x0, q0, s0, z, t, self.step, self.integrator, self.cfg)
        x = integrate(lambda y, tau: self._mlp_velocity(y, tau), x0, 0.0, t, self.step, self.integrator)
        return x, q0, s0

    def base_state_from(self, x, q, s, z, t0, t):
        """The state (x, q, s) at t0 advanced to t by the affine velocity (VG-STEP)."""
        return base_state(self.params(), x, q, s, z, t, self.step, self.integrator, self.cfg, t0=t0)

    def carried_state(self, x0, q0, s0, z, t, t_start):
        """(x, q, s) at time t of scheme (b): the ADF's state at t_start carried to t by the
        velocity (VG-CARRY). Without PDS the MLP velocity carries positions only."""
        if self.pds:
            return carried_state(self.params(), x0, q0, s0, z, t, t_start, self.step, self.integrator, self.cfg)
        xa, qa, sa = compose_state(x0, q0, s0, *self.adf_residual(x0, t_start, z))
        xs = xa.detach()
        xv = integrate(lambda y, tau: self._mlp_velocity(y, tau), xs, t_start, t, self.step, self.integrator)
        return xa + (xv - xs), qa, sa

    def carry_loss(self, x0, q0, s0, z, t_a, t):
        """VG-LOSS-CARRY: mean squared gap between the affine velocity's step t_a -> t from the
        ADF's state and the ADF's position at t (0-d tensor)."""
        return carry_loss(self.params(), x0, q0, s0, z, t_a, t, self.step, self.integrator, self.cfg)

    def adf_residual(self, x0, t, z):
        """(dx, dq, ds) of the auxiliary deformation field (VG-ADF)."""
        return adf_residual(self.params(), x0, t, z, self.cfg)

    def velocity_at(self, x, t):
        """The Eulerian velocity v(x, t) (N, 3) at world points x (N, 3) (VG-FIELD, or the MLP)."""
        if self.pds:
            return velocity_field(self.params(), x, t, self.cfg)
        return self._mlp_velocity(x, t)

    def particle_velocity(self, x0, x, t):
        """Velocity (N, 3) of the particles that started at x0 (N, 3), when at x (N, 3) at time t:
        Φ(x) w(t, E(γ(x0))), the code frozen at the start as along a path (VG-VEL, VG-TRAJ).
        Without PDS the velocity MLP has no code: the Eulerian field at x."""
        if self.pds:
            return velocity(x, coefficients(self.params(), t, self.codes(x0), self.cfg))
        return self._mlp_velocity(x, t)

    def residuals(self, x, t, divergence):
        """(transport residual (N, 3), divergence (N,) or None) at collocation points x (N, 3).

        VG-TRANSPORT and VG-DIV; the divergence is computed only when asked for (the
        transport residual alone needs one JVP instead of three).
        """
        if self.pds:
            if divergence:
                return physics_residuals(self.params(), x, t, self.cfg)
            return transport_residual(self.params(), x, t, self.cfg), None
        return self._mlp_residuals(x, t, divergence)

    def _mlp_velocity(self, x, t):
        t_col = torch.as_tensor(t, dtype=x.dtype, device=x.device).reshape(1, 1).expand(x.shape[0], 1)
        return self._mlp_velocity_xt(x, t_col)

    def _mlp_velocity_xt(self, x, t_col):
        return mlp(_layers(self.velocity_mlp), torch.cat([positional_encoding(x, self.cfg.n_freqs_x), t_col], dim=-1))

    def _mlp_residuals(self, x, t, divergence):
        # The MLP acts on each point alone, so one batched JVP gives every point's
        # directional derivative at once: along t for dv/dt, along v for (grad v) v.
        t_col = torch.full((x.shape[0], 1), float(t), dtype=x.dtype, device=x.device)
        v, dv_dt = jvp(lambda s: self._mlp_velocity_xt(x, s), (t_col,), (torch.ones_like(t_col),))
        _, grad_v_v = jvp(lambda y: self._mlp_velocity_xt(y, t_col), (x,), (v,))
        r = dv_dt + grad_v_v - acceleration_field(self.params(), x, t, self.cfg)
        div = None
        if divergence:
            div = sum(jvp(lambda y: self._mlp_velocity_xt(y, t_col), (x,), (e.expand_as(x),))[1][:, k]
                      for k, e in enumerate(torch.eye(3, dtype=x.dtype, device=x.device)))
        return r, div


def motion_config(model_cfg, profile):
    """The `MotionConfig` of a training `ModelConfig` and a scene's `MotionProfile`."""
    sizes = {name: getattr(model_cfg, name) for name in _NETWORK_SIZES}
    return MotionConfig(**sizes, mask=profile.mask, acc_mask=profile.acc_mask)


# The MotionConfig fields that ModelConfig carries under the same names.
_NETWORK_SIZES = ("n_freqs_x", "n_freqs_t", "n_freqs_adf_x", "n_freqs_adf_t", "code_dim", "n_patterns", "hidden",
                  "depth")


def _velocity_mlp_layers(rng, cfg):
    """v(γ(x), t): 3 (1 + 2 n_freqs_x) + 1 -> hidden^depth -> 3, last layer zero (a still start)."""
    return mlp_layers(rng, 3 * (1 + 2 * cfg.n_freqs_x) + 1, cfg.hidden, cfg.depth, 3, zero_last=True)


def _parameter_list(layers):
    return nn.ParameterList([nn.Parameter(torch.tensor(a, dtype=torch.float32)) for pair in layers for a in pair])


def _layers(plist):
    items = list(plist)
    return list(zip(items[0::2], items[1::2]))
