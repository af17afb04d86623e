"""Transport and divergence residuals of the Eulerian velocity field, in torch.

Twin of `velogauss_ref.physics.residuals` (spec/physics.md, VG-TRANSPORT, VG-DIV and
VG-TRANSPORT-MLP).

The reference differentiates v(x, t) = Phi(x) w(t, E(gamma(x))) with reverse mode, one
point at a time. Here the whole batch is done at once from the structure of v:
- Phi is linear in x, so with w held fixed grad_x v = A(w) exactly;
- v is linear in w, so the rest of grad_x v is Phi(x) (dw/dx), and only the code path
  x -> m(E(gamma(x))) needs differentiating: forward-mode JVPs (torch.func.jvp), batched
  over all points at once because each point's mixing weights depend on that point alone;
- dw/dt = m(z) dP/dt needs one JVP of the time network (K x 12 values) per time.
Every JVP here composes with reverse mode, so the residuals backpropagate to the
parameters (and to x) as the physics loss requires.
"""

import torch
from torch.func import jvp, vmap

from velogauss_fast.checks import check_array
from velogauss_fast.motion.basis import affine_from_coefficients
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import masked, mixing_weights, motion_patterns
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.motion.velocity import mlp_velocity, velocity
from velogauss_fast.physics.acceleration import acceleration_coefficients, acceleration_field


def transport_residual(params, x, t, cfg):
    """r = dv/dt + (grad v) v - a at collocation points (VG-TRANSPORT; paper eq. 7).

    params: motion parameter dict; x: (N, 3) collocation points; t: scalar time (number or
    0-d tensor); cfg: MotionConfig -> r: (N, 3). grad v includes the dependence of the code
    on x; (grad v) v is A(w) v plus one JVP of the code path along v.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    P, dP_dt = _patterns_and_rate(params, t, cfg, x)
    m_of_x = _mixing_of_x(params, cfg)
    m = m_of_x(x)
    w = masked(m @ P, cfg.mask)
    v = velocity(x, w)
    _, dm_v = jvp(m_of_x, (x,), (v,))  # d m / d x along v, [N, K]
    A, _ = affine_from_coefficients(w)
    grad_v_v = (A * v[:, None, :]).sum(-1) + velocity(x, masked(dm_v @ P, cfg.mask))
    dv_dt = velocity(x, masked(m @ dP_dt, cfg.mask))
    return dv_dt + grad_v_v - velocity(x, acceleration_coefficients(params, t, m, cfg))


def divergence(params, x, t, cfg):
    """div v = trace(grad v) at collocation points (VG-DIV; paper eq. 8).

    params: motion parameter dict; x: (N, 3); t: scalar time; cfg: MotionConfig -> (N,).
    Equals w7 + w8 + w9 where the coefficients do not vary with x.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    _, _, grad_v, _ = _velocity_jet(params, x, t, cfg)
    return grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def physics_residuals(params, x, t, cfg):
    """(transport residual (N, 3), divergence (N,)) from one shared evaluation of grad v.

    Same values as `transport_residual` and `divergence`, for a training step that needs
    both: the code path is differentiated once along the three axes and (grad v) v is then
    a 3 x 3 product instead of a further JVP.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    v, dv_dt, grad_v, m = _velocity_jet(params, x, t, cfg)
    r = dv_dt + (grad_v * v[:, None, :]).sum(-1) - velocity(x, acceleration_coefficients(params, t, m, cfg))
    return r, grad_v.diagonal(dim1=-2, dim2=-1).sum(-1)


def _velocity_jet(params, x, t, cfg):
    """v (N, 3), dv/dt (N, 3), grad v (N, 3, 3) [i, j] = dv_i/dx_j, and m(x) (N, K)."""
    P, dP_dt = _patterns_and_rate(params, t, cfg, x)
    m_of_x = _mixing_of_x(params, cfg)
    axes = torch.eye(3, dtype=x.dtype, device=x.device)[:, None, :].expand(3, x.shape[0], 3)
    # One JVP per coordinate axis, vmapped: the primal m is computed once, the three
    # tangents dm/dx_j (3, N, K) together.
    m, dm_dx = vmap(lambda e: jvp(m_of_x, (x,), (e,)), out_dims=(None, 0))(axes)
    w = masked(m @ P, cfg.mask)
    A, _ = affine_from_coefficients(w)
    # Column j of grad v: A(w) e_j + Phi(x) dw/dx_j.
    dv_code = velocity(x, masked(dm_dx @ P, cfg.mask))  # [3, N, 3], indexed [j, n, i]
    grad_v = A + dv_code.permute(1, 2, 0)
    v = velocity(x, w)
    dv_dt = velocity(x, masked(m @ dP_dt, cfg.mask))
    return v, dv_dt, grad_v, m


def _mixing_of_x(params, cfg):
    """x (N, 3) -> m(E(gamma(x))) (N, K): the only path through which w depends on x."""
    return lambda x: mixing_weights(params, physics_code(params, x, cfg))


def _patterns_and_rate(params, t, cfg, like):
    """P(t) and dP/dt (both (K, 12)) from one JVP of the time network."""
    t0 = time_tensor(t, like).reshape(())
    return jvp(lambda s: motion_patterns(params, s, cfg), (t0,), (torch.ones_like(t0),))


def mlp_residuals(params, x, t, cfg, with_divergence=False):
    """Transport residual (N, 3) and divergence (N,) or None of the no-pds MLP velocity (VG-TRANSPORT-MLP).

    The velocity is VG-VEL-MLP's, v = MLP_v([gamma(x), t]), at each collocation point.

    params: dict with "velocity_mlp", "code", "mix" and "acc"; x: (N, 3); t: scalar time;
    cfg: MotionConfig; with_divergence: also return div v (VG-DIV), else None. The MLP acts on
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
