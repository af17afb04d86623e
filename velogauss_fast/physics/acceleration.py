"""Acceleration field a(x, t) = Phi(x) alpha(t, E(gamma(x))), in torch.

Twin of `velogauss_ref.physics.acceleration` (spec/physics.md, VG-ACC, VG-ACC-RIGID and
VG-ACC-HARM).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import centred, masked, mixing_weights
from velogauss_fast.motion.scalars import check_time
from velogauss_fast.motion.velocity import velocity


def acceleration_field(params, x, t, cfg):
    """a(x, t) = Phi(x) alpha(t, m(z)) with z = E(gamma(x)), masked by cfg.acc_mask (VG-ACC, VG-ACC-RIGID).

    params: motion parameter dict (uses "code", "mix" and "acc": Q (ACC_POLY_DEGREE + 1, K, 12)
    when cfg.acc_form is "poly", R (K, 12) when "rigid", Q (2 ACC_HARMONICS + 1, K, 12) and the
    patterns' frequency, "time"[0][1], when "harmonic"); x: (N, 3) points; t: scalar time;
    cfg: MotionSpec -> a: (N, 3), world units per unit time squared. All-zero Q (scenes
    without acceleration) gives a = 0.
    The acceleration's own mask cfg.acc_mask, not the velocity's cfg.mask, applies: the
    material derivative of a masked velocity field can need columns the velocity lacks.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    m = mixing_weights(params, physics_code(params, x, cfg))
    return velocity(x, acceleration_coefficients(params, t, m, cfg))


def acceleration_coefficients(params, t, m, cfg):
    """alpha (N, 12), masked by cfg.acc_mask, for mixing weights m (N, K): m sum_d Q_d t^d
    (VG-ACC), rigid_patterns(m R, t) (VG-ACC-RIGID) or m harmonic_patterns(Q, Omega, t)
    (VG-ACC-HARM). The coefficients `acceleration_field`
    applies Phi(x) to, for callers that already hold m at the points (the physics residuals
    share it with the velocity). The polynomial's and the harmonics' patterns are written about
    params["centre"] when the dict holds it (VG-COEF-CENTRE), as the velocity's are."""
    check_time("t", t)
    check_array("m", m, (None, cfg.n_patterns))
    if cfg.acc_form == "poly":
        return masked(m @ centred(polynomial_patterns(params["acc"], t), params.get("centre")), cfg.acc_mask)
    if cfg.acc_form == "harmonic":
        return masked(m @ centred(harmonic_patterns(params["acc"], params["time"][0][1], t), params.get("centre")),
                      cfg.acc_mask)
    # The rigid bodies' parameters are mixed, not their accelerations: a mixture of rigid
    # accelerations with different spins and centres is a general quadratic in t again.
    return masked(rigid_patterns(m @ params["acc"], t), cfg.acc_mask)


def polynomial_patterns(Q, t):
    """sum_d Q_d t^d: Q (D + 1, K, 12) -> (K, 12), the acceleration of each motion pattern,
    by Horner's rule (VG-ACC)."""
    out = Q[-1]
    for Qd in Q.flip(0)[1:]:
        out = out * t + Qd
    return out


def harmonic_patterns(Q, omega, t):
    """sum_d Q_d phi_d(Omega t) (VG-ACC-HARM): Q (2 J + 1, K, 12), omega (1,) the patterns'
    frequency, t scalar -> (K, 12), with phi = (1, cos theta, sin theta, ..., cos J theta,
    sin J theta), J = ACC_HARMONICS."""
    theta = omega * t  # [1]
    phi = [torch.ones_like(theta)]
    for j in range(1, (Q.shape[0] - 1) // 2 + 1):
        phi += [torch.cos(j * theta), torch.sin(j * theta)]
    return (Q * torch.stack(phi)[:, :, None]).sum(0)


def rigid_patterns(R, t):
    """The coefficients of a(x, t) = g + Omega^2 (x - c(t)) per rigid body (VG-ACC-RIGID).

    R: (..., 12), rows (omega, g, c0, u) with c(t) = c0 + u t + g t^2 / 2 -> (..., 12) in
    VG-BASIS order: translation g - Omega^2 c(t), rotation 0, stretch diag(Omega^2), shear
    (Omega^2_xy, Omega^2_yz, Omega^2_xz), with Omega^2 = omega omega^T - |omega|^2 I.
    """
    omega, g, c0, u = R.split(3, dim=-1)
    c = c0 + u * t + 0.5 * g * (t * t)
    spin2 = (omega * omega).sum(-1, keepdim=True)
    omega2_c = omega * (omega * c).sum(-1, keepdim=True) - spin2 * c  # Omega^2 c
    wx, wy, wz = omega.unbind(-1)
    shear = torch.stack([wx * wy, wy * wz, wx * wz], dim=-1)
    return torch.cat([g - omega2_c, torch.zeros_like(omega), omega * omega - spin2, shear], dim=-1)
