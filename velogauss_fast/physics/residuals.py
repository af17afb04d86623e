"""Transport and divergence residuals of the Eulerian velocity field, in torch.

Twin of `velogauss_ref.physics.residuals` (spec/physics.md, VG-TRANSPORT, VG-DIV and
VG-TRANSPORT-MLP).

The reference differentiates v(x, t) = Phi(x) w(t, E(gamma(x))) with reverse mode, one
point at a time. Here the whole batch is done at once from the structure of v:
- Phi is linear in x, so with w held fixed grad_x v = A(w) exactly;
- v is linear in w, so the rest of grad_x v is Phi(x) (dw/dx), and only the code path
  x -> m(E(gamma(x))) needs differentiating: forward mode written out for its known layers
  (`positional_encoding_jet`, `mlp_jet`, `mixing_weights_jet`), the three axis tangents of
  every point carried through one pass beside the values (each point's mixing weights
  depend on that point alone);
- dw/dt = m(z) dP/dt needs one tangent through the time network (K x 12 values) per time,
  or for rigid patterns (VG-COEF-RIGID) their closed-form rate.
These are plain differentiable ops, so the residuals backpropagate to the parameters (and
to x) as the physics loss requires. Written out instead of torch.func's vmap(jvp), the
forward takes less than half the time and forward + backward about 1/1.6 of it on 1,024
points (the backward, reverse mode through the same tangents, costs about the same);
benchmarks/RESULTS.md, "Training step: before / after".
"""

import torch
from torch.func import jvp

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import affine_from_coefficients
from velogauss_fast.motion.coefficients import (centred, harmonic_velocity_patterns_jet, masked, mixing_weights_jet,
                                               rigid_velocity_patterns_jet)
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.motion.velocity import mlp_velocity, velocity
from velogauss_fast.nn import mlp_jet, positional_encoding_jet
from velogauss_fast.physics.acceleration import acceleration_coefficients, acceleration_field


def transport_residual(params, x, t, cfg):
    """r = dv/dt + (grad v) v - a at collocation points (VG-TRANSPORT; paper eq. 7).

    params: motion parameter dict; x: (N, 3) collocation points; t: scalar time (number or
    0-d tensor); cfg: MotionSpec -> r: (N, 3). grad v includes the dependence of the code
    on x.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    return _transport(params, x, t, cfg, *_velocity_jet(params, x, t, cfg))


def divergence(params, x, t, cfg):
    """div v = trace(grad v) at collocation points (VG-DIV; paper eq. 8).

    params: motion parameter dict; x: (N, 3); t: scalar time; cfg: MotionSpec -> (N,).
    Equals w7 + w8 + w9 where the coefficients do not vary with x.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    _, _, grad_v, _ = _velocity_jet(params, x, t, cfg)
    return grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def physics_residuals(params, x, t, cfg):
    """(transport residual (N, 3), divergence (N,)) from one shared evaluation of grad v.

    Same values as `transport_residual` and `divergence`, for a training step that needs
    both: the code path is differentiated once along the three axes for both.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    jet = _velocity_jet(params, x, t, cfg)
    grad_v = jet[2]
    return _transport(params, x, t, cfg, *jet), grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def _transport(params, x, t, cfg, v, dv_dt, grad_v, m):
    """r = dv/dt + (grad v) v - a (N, 3) from `_velocity_jet`'s outputs."""
    return dv_dt + (grad_v * v[:, None, :]).sum(-1) - velocity(x, acceleration_coefficients(params, t, m, cfg))


def _velocity_jet(params, x, t, cfg):
    """v (N, 3), dv/dt (N, 3), grad v (N, 3, 3) [i, j] = dv_i/dx_j, and m(x) (N, K)."""
    P, dP_dt = _patterns_and_rate(params, t, cfg, x)
    # z = E(gamma(x)) (VG-CODE) and m(z), each with its derivatives along the 3 axes.
    gamma, d_gamma = positional_encoding_jet(x, cfg.n_freqs_x)  # [N, E], [3, N, E]
    z, dz_dx = mlp_jet(params["code"], gamma, d_gamma)  # [N, L], [3, N, L]
    m, dm_dx = mixing_weights_jet(params, z, dz_dx)  # [N, K], [3, N, K]
    w = masked(m @ P, cfg.mask)
    A, _ = affine_from_coefficients(w)
    # Column j of grad v: A(w) e_j + Phi(x) dw/dx_j.
    dv_code = velocity(x, masked(dm_dx @ P, cfg.mask))  # [3, N, 3], indexed [j, n, i]
    grad_v = A + dv_code.permute(1, 2, 0)
    v = velocity(x, w)
    dv_dt = velocity(x, masked(m @ dP_dt, cfg.mask))
    return v, dv_dt, grad_v, m


def _patterns_and_rate(params, t, cfg, like):
    """P(t) and dP/dt (both (K, 12)) from one pass of the time network with one tangent; the
    time network's and the oscillators' written about params["centre"] (VG-COEF-CENTRE, linear
    in P, so the rate goes through it as the patterns do)."""
    t0 = time_tensor(t, like)[:, None]  # [1, 1]
    if cfg.pattern_form == "rigid":
        return rigid_velocity_patterns_jet(params["time"], t0, cfg.max_time)
    if cfg.pattern_form == "harmonic":
        P, dP_dt = harmonic_velocity_patterns_jet(*params["time"][0], t0)
    else:
        gamma, d_gamma = positional_encoding_jet(t0, cfg.n_freqs_t)  # [1, E], [1, 1, E]
        P, dP_dt = mlp_jet(params["time"], gamma, d_gamma)  # [1, 12 K], [1, 1, 12 K]
    centres = params.get("centre")
    return centred(P.reshape(-1, 12), centres), centred(dP_dt.reshape(-1, 12), centres)


def mlp_residuals(params, x, t, cfg, with_divergence=False):
    """Transport residual (N, 3) and divergence (N,) or None of the no-pds MLP velocity (VG-TRANSPORT-MLP).

    The velocity is VG-VEL-MLP's, v = MLP_v([gamma(x), t]), at each collocation point.

    params: dict with "velocity_mlp", "code", "mix" and "acc"; x: (N, 3); t: scalar time;
    cfg: MotionSpec; with_divergence: also return div v (VG-DIV), else None. The MLP acts on
    each point alone, so one batched JVP gives every point's directional derivative at once:
    along t for dv/dt, along v for (grad v) v, along each axis for the divergence.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    t0 = time_tensor(t, x).reshape(())
    v, dv_dt = jvp(lambda s: mlp_velocity(params, x, s, cfg), (t0,), (torch.ones_like(t0),))
    _, grad_v_v = jvp(lambda y: mlp_velocity(params, y, t, cfg), (x,), (v,))
    r = dv_dt + grad_v_v - acceleration_field(params, x, t, cfg)
    if not with_divergence:
        return r, None
    div = sum(jvp(lambda y: mlp_velocity(params, y, t, cfg), (x,), (e.expand_as(x),))[1][:, k]
              for k, e in enumerate(torch.eye(3, dtype=x.dtype, device=x.device)))
    return r, div
