"""Acceleration field a(x, t) = Phi(x) alpha(t, E(gamma(x))), in torch.

Twin of `velogauss_ref.physics.acceleration` (spec/physics.md, VG-ACC).
"""

from velogauss_fast.checks import check_array
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import masked, mixing_weights
from velogauss_fast.motion.scalars import check_time
from velogauss_fast.motion.velocity import velocity


def acceleration_field(params, x, t, cfg):
    """a(x, t) = Phi(x) m(z) sum_d Q_d t^d with z = E(gamma(x)), masked by cfg.acc_mask (VG-ACC).

    params: motion parameter dict (uses "code", "mix" and "acc" = Q (ACC_POLY_DEGREE + 1,
    K, 12)); x: (N, 3) points; t: scalar time; cfg: MotionConfig -> a: (N, 3), world units
    per unit time squared. All-zero Q (scenes without acceleration) gives a = 0.
    The acceleration's own mask cfg.acc_mask, not the velocity's cfg.mask, applies: the
    material derivative of a masked velocity field can need columns the velocity lacks.
    """
    check_array("x", x, (None, 3))
    check_time("t", t)
    m = mixing_weights(params, physics_code(params, x, cfg))
    return velocity(x, acceleration_coefficients(params, t, m, cfg))


def acceleration_coefficients(params, t, m, cfg):
    """alpha = m sum_d Q_d t^d (N, 12), masked by cfg.acc_mask, for mixing weights m (N, K)
    (VG-ACC): the coefficients `acceleration_field` applies Phi(x) to, for callers that
    already hold m at the points (the physics residuals share it with the velocity)."""
    check_time("t", t)
    check_array("m", m, (None, params["acc"].shape[1]))
    return masked(m @ acceleration_patterns(params["acc"], t), cfg.acc_mask)


def acceleration_patterns(Q, t):
    """sum_d Q_d t^d: Q (D + 1, K, 12) -> (K, 12), the acceleration of each motion pattern,
    by Horner's rule."""
    out = Q[-1]
    for Qd in Q.flip(0)[1:]:
        out = out * t + Qd
    return out
