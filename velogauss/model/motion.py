"""The motion of a model: its parameters as a module, and pure functions of (params, spec).

`MotionParameters` holds the motion parameter dict of spec/motion.md as trainable
parameters and does nothing else; `params()` returns the dict, built once per training step.
Everything the motion computes is a pure function of that dict and the resolved
`MotionSpec` (velogauss_core.motion), evaluated with `velogauss_fast` (VG-CODE ... VG-DIV):

- `gaussians_at`: the Gaussians at time t (the spec's scheme, then the ADF residual);
- `carry_loss`: VG-LOSS-CARRY, the velocity fitted to the ADF's paths (scheme "adf-step");
- `velocity_at`, `particle_velocity`: the learned velocities (Eulerian, and along paths),
  the code taken from the network; `own_mixing` and `velocity_with_mixing` build them from
  given mixing weights (VG-FIELD-GAUSS, which `velogauss.model.velogauss_model` interpolates);
- `motion_residuals`: the physics residuals of the training loss.

Under `spec.future = "hold"` the state and velocities past `spec.max_time` are those of the
persistence forecast (`held`); the physics residuals, a training loss, read the field as it is.

What is built follows the spec: the velocity's time network ("affine", PDS) or the
unconstrained velocity MLP ("mlp", no-pds) or neither (deform-only); the acceleration
polynomial Q only when the spec accelerates; the ADF only when the ablation keeps it.
"""

import functools

import numpy as np
import torch
from torch import nn

from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_core.motion import N_BASIS, MotionSpec, carry_start, init_motion_params, mlp_layers, network_shapes
from velogauss_fast.motion import carry
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import coefficients, mixed_coefficients, mixing_weights
from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.motion.integrate import integrate
from velogauss_fast.motion.params import params_to_torch
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.velocity import mlp_velocity, velocity, velocity_field
from velogauss_fast.physics.residuals import mlp_residuals, physics_residuals, transport_residual


class MotionParameters(nn.Module):
    """The trainable motion parameters of a moving scene, laid out as `spec` says.

    Attributes (each a ParameterList of W, b, W, b, ...): code (VG-CODE), mix (VG-COEF),
    time (VG-COEF, velocity "affine": the time network, VG-COEF-HARM's (C, Omega) under
    spec.pattern_form "harmonic", or VG-COEF-RIGID's B, a Parameter, under "rigid"),
    velocity_mlp (velocity "mlp"), adf (VG-ADF); acc (VG-ACC's or VG-ACC-HARM's Q or
    VG-ACC-RIGID's R, a Parameter) when the spec accelerates; centre, a buffer (K, 3), the
    patterns' centres (VG-COEF-CENTRE), zero until set. rng: NumPy Generator of the initial
    weights (`velogauss_core.motion.init_motion_params`, then the velocity MLP's layers).
    """

    def __init__(self, spec: MotionSpec, rng: np.random.Generator):
        super().__init__()
        if not spec.moving:
            raise ValueError("spec: a static scene has no motion parameters (spec.moving is False)")
        self.spec = spec
        params = params_to_torch(init_motion_params(rng, spec), torch.float32, "cpu")
        self.code = _parameter_list(params["code"])
        self.mix = _parameter_list(params["mix"])
        if spec.rigid_patterns:
            self.time = nn.Parameter(params["time"])
        elif spec.velocity == "affine":
            self.time = _parameter_list(params["time"])
        elif spec.velocity == "mlp":
            d_in, d_out = network_shapes(spec)["velocity_mlp"]
            # Last layer zero: a still start, like the affine velocity's time network.
            layers = mlp_layers(rng, d_in, spec.hidden, spec.depth, d_out, zero_last=True)
            self.velocity_mlp = _parameter_list(params_to_torch(layers, torch.float32, "cpu"))
        if spec.acceleration:
            self.acc = nn.Parameter(params["acc"])
        if spec.adf:
            self.adf = _parameter_list(params["adf"])
        # The patterns' centres (VG-COEF-CENTRE): data, not a trained parameter; the world's
        # origin until training places them (velogauss.train.mixing.place_patterns).
        self.register_buffer("centre", params["centre"])

    def params(self) -> dict:
        """The spec's parameter dict; a scene without acceleration gets Q = 0 (a ≡ 0), not a parameter."""
        spec = self.spec
        ref = self.code[0]
        acc = self.acc if spec.acceleration else ref.new_zeros(ACC_POLY_DEGREE + 1, spec.n_patterns, N_BASIS)
        out = {"code": _layers(self.code), "mix": _layers(self.mix), "acc": acc, "centre": self.centre}
        for name in ("time", "velocity_mlp", "adf"):
            value = getattr(self, name, None)
            if value is not None:
                out[name] = value if isinstance(value, nn.Parameter) else _layers(value)
        return out


def held(spec: MotionSpec, t) -> bool:
    """Whether t lies past the observed window of a model that holds its motion there
    (spec.future "hold"): its Gaussians then keep their state at spec.max_time, with zero velocity."""
    return spec.future == "hold" and float(t) > spec.max_time


def inline_adf(params: dict, x0: torch.Tensor, t, z: torch.Tensor, cfg):
    """`gaussians_at`'s default evaluation of the ADF's residual: a function returning
    `adf_residual(params, x0, t, z, cfg)` (dx (N, 3), dq (N, 4), ds (N, 3)), computed when called."""
    return functools.partial(adf_residual, params, x0, t, z, cfg)


def gaussians_at(params: dict, spec: MotionSpec, x0: torch.Tensor, q0: torch.Tensor, s0: torch.Tensor, t,
                 offset: float = 0.0, adf=None):
    """(means (N, 3), quats (N, 4) unit, scales (N, 3), base means x* (N, 3)) at time t of the
    Gaussians whose canonical state is x0 (N, 3), q0 (N, 4) unit, s0 (N, 3) > 0.

    Scheme "integrate", paper eqs. 5-6 (VG-TRAJ, VG-ADF, VG-ADF-COMPOSE): z = E(γ(x0)); the
    base state (x*, q*, s*) integrated from t = 0; x = x* + Δx, q = q* ⊗ Δq, s = s* exp(Δs)
    with (Δx, Δq, Δs) = ADF(x0, t_adf, z) when spec.adf, t_adf = min(t, spec.adf_clamp_time).
    Without a velocity (deform-only) x* = x0; without PDS only positions move.
    Scheme "adf-step" (VG-CARRY): the ADF's state at t_start = carry_start(t, offset,
    spec.carry_until) carried to t by the velocity; the base means are then the means.
    offset: the signed step training draws (±spec.carry_offset), 0 in evaluation; only
    "adf-step" reads it.
    adf: how scheme "integrate" evaluates the ADF's residual, `adf(params, x0, t_adf, z,
    spec)` called before the integration and returning a function that gives (Δx, Δq,
    Δs) after it; None: `inline_adf`. Training passes one whose backward overlaps the
    integration's (velogauss.train.loop).
    Past the window under spec.future "hold" this is the state at spec.max_time (`held`).
    """
    if held(spec, t):
        t = spec.max_time
    z = physics_code(params, x0, spec)
    if spec.scheme == "adf-step":
        x, q, s = _carried_state(params, spec, x0, q0, s0, z, t, carry_start(t, offset, spec.carry_until))
        return x, q, s, x
    if spec.scheme != "integrate":
        raise ValueError(f"spec.scheme: unknown scheme {spec.scheme!r}")
    if spec.adf:
        t_adf = t if spec.adf_clamp_time is None else min(float(t), spec.adf_clamp_time)
        # Before the integration, so that an evaluation may place graph nodes on either side of it.
        residual = (inline_adf if adf is None else adf)(params, x0, t_adf, z, spec)
    xs, qs, ss = _integrated_state(params, spec, x0, q0, s0, z, t)
    if not spec.adf:
        return xs, qs, ss, xs
    dx, dq, ds = residual()
    x, q, s = compose_state(xs, qs, ss, dx, dq, ds)
    return x, q, s, xs


def velocity_at(params: dict, spec: MotionSpec, x: torch.Tensor, t) -> torch.Tensor:
    """The Eulerian velocity v(x, t) (N, 3) at world points x (N, 3) (VG-FIELD, or the MLP's
    VG-VEL-MLP); zero without a velocity, and past the window of a held motion (`held`)."""
    if held(spec, t):
        return torch.zeros_like(x)
    if spec.velocity == "affine":
        return velocity_field(params, x, t, spec)
    if spec.velocity == "mlp":
        return mlp_velocity(params, x, t, spec)
    return torch.zeros_like(x)


def particle_velocity(params: dict, spec: MotionSpec, x0: torch.Tensor, x: torch.Tensor, t) -> torch.Tensor:
    """Velocity (N, 3) of the particles that started at x0 (N, 3), when at x (N, 3) at time t:
    Φ(x) w(t, E(γ(x0))), the code frozen at the start as along a path (VG-VEL, VG-TRAJ).
    Without PDS the velocity MLP has no code: the Eulerian field at x. Zero without a velocity,
    and past the window of a held motion (`held`)."""
    if held(spec, t):
        return torch.zeros_like(x)
    if spec.velocity == "affine":
        return velocity(x, coefficients(params, t, physics_code(params, x0, spec), spec))
    return velocity_at(params, spec, x, t)


def own_mixing(params: dict, spec: MotionSpec, x0: torch.Tensor) -> torch.Tensor:
    """The mixing weights m(E(γ(x0))) (N, K) of the particles at canonical x0 (N, 3) (VG-CODE,
    VG-COEF): what each Gaussian moves with."""
    return mixing_weights(params, physics_code(params, x0, spec))


def velocity_with_mixing(params: dict, spec: MotionSpec, x: torch.Tensor, t, m: torch.Tensor) -> torch.Tensor:
    """Φ(x) (m P(t)) (N, 3), masked as VG-COEF, at points x (N, 3) with mixing weights m (N, K):
    the velocity of VG-FIELD-GAUSS, whose m is interpolated from the Gaussians' own; zero past
    the window of a held motion (`held`)."""
    if held(spec, t):
        return torch.zeros_like(x)
    return velocity(x, mixed_coefficients(params, t, m, spec))


def motion_residuals(params: dict, spec: MotionSpec, x: torch.Tensor, t):
    """(transport residual (N, 3), divergence (N,) or None) at collocation points x (N, 3).

    VG-TRANSPORT (VG-TRANSPORT-MLP without PDS) and VG-DIV; the divergence is computed only
    when spec.divergence (the affine field shares one grad v between the two).
    """
    if spec.velocity == "affine":
        if spec.divergence:
            return physics_residuals(params, x, t, spec)
        return transport_residual(params, x, t, spec), None
    if spec.velocity == "mlp":
        return mlp_residuals(params, x, t, spec, with_divergence=spec.divergence)
    raise ValueError("spec.velocity: a model without velocity has no physics residuals")


def carry_loss(params: dict, spec: MotionSpec, x0: torch.Tensor, q0: torch.Tensor, s0: torch.Tensor, t_a, t):
    """VG-LOSS-CARRY (0-d tensor): mean squared gap between the affine velocity's step t_a -> t
    from the ADF's state at t_a and the ADF's position at t, for the Gaussians whose canonical
    state is x0 (N, 3), q0 (N, 4), s0 (N, 3). Only the velocity (and the code) learns from it.
    Needs spec.carry_loss (scheme "adf-step", affine velocity)."""
    if not spec.carry_loss:
        raise ValueError("spec.carry_loss: VG-LOSS-CARRY needs scheme \"adf-step\" and the affine velocity")
    z = physics_code(params, x0, spec)
    return carry.carry_loss(params, x0, q0, s0, z, t_a, t, spec.step, spec.integrator, spec)


def _carried_state(params, spec, x0, q0, s0, z, t, t_start):
    """Scheme "adf-step": (x, q, s) at t, the ADF's state at t_start carried to t by the
    velocity (VG-CARRY). Without PDS the velocity MLP carries positions only (rotations and
    scales stay the ADF's at t_start), with the same stop-gradient on the start."""
    if spec.velocity == "affine":
        return carry.carried_state(params, x0, q0, s0, z, t, t_start, spec.step, spec.integrator, spec)
    xa, qa, sa = carry.adf_state(params, x0, q0, s0, z, t_start, spec)
    xs = xa.detach()
    xv = integrate(lambda y, tau: mlp_velocity(params, y, tau, spec), xs, t_start, t, spec.step,
                   spec.integrator)
    return xa + (xv - xs), qa, sa


def _integrated_state(params, spec, x0, q0, s0, z, t):
    """Scheme "integrate": (x*, q*, s*) by integration from t = 0 (VG-TRAJ)."""
    if spec.velocity == "affine":
        return base_state(params, x0, q0, s0, z, t, spec.step, spec.integrator, spec)
    if spec.velocity == "mlp":
        x = integrate(lambda y, tau: mlp_velocity(params, y, tau, spec), x0, 0.0, t, spec.step,
                      spec.integrator)
        return x, q0, s0
    return x0, q0, s0


def _parameter_list(layers):
    return nn.ParameterList([nn.Parameter(a) for pair in layers for a in pair])


def _layers(plist):
    items = list(plist)
    return list(zip(items[0::2], items[1::2]))
