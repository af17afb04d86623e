"""Transport (momentum) and divergence residuals of the Eulerian velocity field.

spec/physics.md, VG-TRANSPORT, VG-DIV (paper eqs. 7-8) and VG-TRANSPORT-MLP. Every derivative is taken by
`autograd`, one collocation point at a time, through the whole field
v(x, t) = Phi(x) w(t, E(gamma(x))) -- the code's dependence on x included. Slow and exact:
the fast path's structured forward-mode derivatives are tested against these.
"""

import dataclasses

import autograd.numpy as np
from autograd import jacobian

from velogauss_ref.checks import check_array, check_scalar
from velogauss_ref.motion.velocity import mlp_velocity, velocity_field
from velogauss_ref.physics.acceleration import acceleration_field


def transport_residual(params, x, t, cfg):
    """r = dv/dt + (grad v) v - a at each collocation point (VG-TRANSPORT; paper eq. 7).

    params: motion parameter dict; x: (N, 3) collocation points; t: scalar time, any real
    value; cfg: MotionSpec -> r: (N, 3). (grad v)_ij = dv_i/dx_j of VG-FIELD, including
    the dependence of the code on x; a from VG-ACC (masked by cfg.acc_mask). r = 0 where
    the field's material acceleration Dv/Dt is exactly the modelled a.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    dv_dt, grad_v = velocity_derivatives(params, x, t, cfg)
    v = velocity_field(params, x, t, _own_patterns(cfg))
    return dv_dt + np.einsum("nij,nj->ni", grad_v, v) - acceleration_field(params, x, t, cfg)


def divergence(params, x, t, cfg):
    """div v = trace(grad v) at each collocation point (VG-DIV; paper eq. 8).

    params: motion parameter dict; x: (N, 3); t: scalar time; cfg: MotionSpec -> (N,).
    Equals w7 + w8 + w9 where the coefficients do not vary with x.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    _, grad_v = velocity_derivatives(params, x, t, cfg)
    return grad_v[:, 0, 0] + grad_v[:, 1, 1] + grad_v[:, 2, 2]


def velocity_derivatives(params, x, t, cfg):
    """(dv/dt (N, 3), grad v (N, 3, 3) with [n, i, j] = dv_i/dx_j) of VG-FIELD at each x_n.

    One autograd Jacobian of v with respect to the point's (x, y, z, t) per point: v at x_n
    depends on x_n alone, so this is exactly the per-point derivative. No points (N = 0)
    give empty arrays.
    """
    field = _own_patterns(cfg)
    return _point_derivatives(lambda y, s: velocity_field(params, y, s, field), x, t)


def _own_patterns(cfg):
    """`cfg` read with its forms' own patterns at every time: the residuals, a training loss, do
    not coast past the window (VG-COEF-COAST; the fast path's closed-form rates never do)."""
    return dataclasses.replace(cfg, future="integrate")


def mlp_residuals(params, x, t, cfg, with_divergence=False):
    """Transport residual (N, 3) and divergence (N,) or None of the no-pds MLP velocity (VG-TRANSPORT-MLP).

    The velocity is VG-VEL-MLP's, evaluated at each collocation point.

    r = dv/dt + (grad v) v - a with v = MLP_v([gamma(x), t]) and a from VG-ACC (the same
    acceleration field as with PDS); div v = trace(grad v) when `with_divergence`, else None.
    params: dict with "velocity_mlp", "code", "mix" and "acc"; x: (N, 3); t: scalar time.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    dv_dt, grad_v = _point_derivatives(lambda y, s: mlp_velocity(params, y, s, cfg), x, t)
    v = mlp_velocity(params, x, t, cfg)
    r = dv_dt + np.einsum("nij,nj->ni", grad_v, v) - acceleration_field(params, x, t, cfg)
    div = grad_v[:, 0, 0] + grad_v[:, 1, 1] + grad_v[:, 2, 2] if with_divergence else None
    return r, div


def _point_derivatives(field, x, t):
    """(dv/dt (N, 3), grad v (N, 3, 3)) of the field (x (M, 3), t) -> v (M, 3), per point.

    One autograd Jacobian with respect to the point's (x, y, z, t) per point: the fields
    here act on each point alone, so this is exactly the per-point derivative.
    """
    n = np.shape(x)[0]

    def v_at(xt):  # (x, y, z, t) of one point -> v (3,)
        return field(np.reshape(xt[0:3], (1, 3)), xt[3])[0]

    # J_n (3, 4): columns 0..2 are grad v at x_n, column 3 is dv/dt.
    J = [jacobian(v_at)(np.concatenate([x[k], np.reshape(t, (1,))])) for k in range(n)]
    J = np.stack(J) if J else np.zeros((0, 3, 4))
    return J[:, :, 3], J[:, :, 0:3]
