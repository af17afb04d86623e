"""Acceleration field a(x, t) = Phi(x) alpha(t, E(gamma(x))).

spec/physics.md, VG-ACC.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array, check_scalar
from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import masked, mixing_weights
from velogauss_core.motion import N_BASIS
from velogauss_ref.motion.velocity import velocity


def acceleration_field(params, x, t, cfg):
    """a(x, t) = Phi(x) alpha with alpha = m(z) sum_d Q_d t^d, z = E(gamma(x)) (VG-ACC).

    params: motion parameter dict (uses "code", "mix" and "acc" = Q
    (ACC_POLY_DEGREE + 1, K, 12)); x: (N, 3) points; t: scalar time, any real value;
    cfg: MotionConfig -> a: (N, 3), world units per unit of normalised time squared.
    alpha is masked by cfg.acc_mask (not cfg.mask: the acceleration of a masked velocity
    field can need columns the velocity lacks). An all-zero Q gives a = 0.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    Q = params["acc"]
    check_array('params["acc"]', Q, (ACC_POLY_DEGREE + 1, cfg.n_patterns, N_BASIS))
    alpha = mixing_weights(params, physics_code(params, x, cfg)) @ acceleration_patterns(Q, t)
    return velocity(x, masked(alpha, cfg.acc_mask))


def acceleration_patterns(Q, t):
    """sum_d Q_d t^d: Q (D + 1, K, 12) -> (K, 12), the acceleration of each motion pattern.

    The powers t^d are built by products, not t ** d: autograd's derivative of t ** 0 at
    t = 0 is 0 * 0 ** -1 = NaN.
    """
    total, power = np.zeros(np.shape(Q)[1:]), 1.0
    for d in range(np.shape(Q)[0]):
        total = total + Q[d] * power
        power = power * t
    return total
