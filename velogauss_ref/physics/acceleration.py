"""Acceleration field a(x, t) = Phi(x) alpha(t, E(gamma(x))).

spec/physics.md, VG-ACC (a polynomial in t per motion pattern), VG-ACC-RIGID (a rigid
body's acceleration per motion pattern) and VG-ACC-HARM (harmonics of each oscillating
pattern's frequency).
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array, check_scalar
from velogauss_core.constants import ACC_HARMONICS, ACC_POLY_DEGREE
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import centred, masked, mixing_weights
from velogauss_core.motion import N_BASIS
from velogauss_ref.motion.velocity import velocity


def acceleration_field(params, x, t, cfg):
    """a(x, t) = Phi(x) alpha with z = E(gamma(x)), m = m(z) and (VG-ACC, VG-ACC-RIGID,
    VG-ACC-HARM) alpha = m sum_d Q_d t^d ("poly"), alpha = rigid_patterns(m R, t) ("rigid") or
    alpha = m harmonic_patterns(Q, Omega, t) ("harmonic", harmonics of Omega t).

    params: motion parameter dict (uses "code", "mix" and "acc": Q (ACC_POLY_DEGREE + 1, K, 12)
    when cfg.acc_form is "poly", R (K, 12) when it is "rigid", Q (2 ACC_HARMONICS + 1, K, 12)
    and the patterns' frequency Omega = params["time"][0][1] (VG-COEF-HARM) when it is
    "harmonic"); x: (N, 3) points; t: scalar
    time, any real value; cfg: MotionSpec -> a: (N, 3), world units per unit of normalised
    time squared.
    alpha is masked by cfg.acc_mask (not cfg.mask: the acceleration of a masked velocity
    field can need columns the velocity lacks). An all-zero Q gives a = 0. The polynomial's and
    the harmonics' patterns are written about params["centre"] when the dict holds it
    (VG-COEF-CENTRE), as the velocity's are.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    shape = {"poly": (ACC_POLY_DEGREE + 1, cfg.n_patterns, N_BASIS), "rigid": (cfg.n_patterns, N_BASIS),
             "harmonic": (2 * ACC_HARMONICS + 1, cfg.n_patterns, N_BASIS)}[cfg.acc_form]
    check_array('params["acc"]', params["acc"], shape)
    m = mixing_weights(params, physics_code(params, x, cfg))
    if cfg.acc_form == "poly":
        alpha = m @ centred(polynomial_patterns(params["acc"], t), params.get("centre"))
    elif cfg.acc_form == "harmonic":
        alpha = m @ centred(harmonic_patterns(params["acc"], params["time"][0][1], t), params.get("centre"))
    else:
        # The rigid bodies' parameters are mixed, not their accelerations: a mixture of rigid
        # accelerations with different spins and centres is a general quadratic in t again.
        alpha = rigid_patterns(m @ params["acc"], t)
    return velocity(x, masked(alpha, cfg.acc_mask))


def polynomial_patterns(Q, t):
    """sum_d Q_d t^d: Q (D + 1, K, 12) -> (K, 12), the acceleration of each motion pattern (VG-ACC).

    The powers t^d are built by products, not t ** d: autograd's derivative of t ** 0 at
    t = 0 is 0 * 0 ** -1 = NaN.
    """
    total, power = np.zeros(np.shape(Q)[1:]), 1.0
    for d in range(np.shape(Q)[0]):
        total = total + Q[d] * power
        power = power * t
    return total


def harmonic_patterns(Q, omega, t):
    """sum_d Q_d phi_d(Omega t) (VG-ACC-HARM): the acceleration of each oscillating motion
    pattern, at the frequency the patterns share.

    Q: (2 J + 1, K, 12); omega: (1,) the patterns' frequency; scalar t -> (K, 12), with
    phi(theta) = (1, cos theta, sin theta, cos 2 theta, sin 2 theta, ..., cos J theta, sin J theta).
    """
    check_array("omega", omega, (1,))
    theta = omega[0] * t
    total = Q[0]
    for j in range(1, (np.shape(Q)[0] - 1) // 2 + 1):
        total = total + Q[2 * j - 1] * np.cos(j * theta) + Q[2 * j] * np.sin(j * theta)
    return total


def rigid_patterns(R, t):
    """The coefficients of a(x, t) = g + Omega^2 (x - c(t)) per rigid body (VG-ACC-RIGID).

    R: (N, 12), each row (omega, g, c0, u): the spin (Omega y = omega x y), the linear
    acceleration, and the centre and its velocity at t = 0, so c(t) = c0 + u t + g t^2 / 2.
    -> (N, 12) in VG-BASIS order: translation g - Omega^2 c(t), no rotation, stretch
    diag(Omega^2), shear (Omega^2_xy, Omega^2_yz, Omega^2_xz). Omega^2 = omega omega^T - |omega|^2 I
    is symmetric, so it lies on the stretch and shear columns.
    """
    omega, g, c0, u = R[:, 0:3], R[:, 3:6], R[:, 6:9], R[:, 9:12]
    c = c0 + u * t + 0.5 * g * t * t
    spin2 = np.sum(omega * omega, axis=1, keepdims=True)
    omega2_c = omega * np.sum(omega * c, axis=1, keepdims=True) - spin2 * c  # Omega^2 c
    wx, wy, wz = omega[:, 0], omega[:, 1], omega[:, 2]
    shear = np.stack([wx * wy, wy * wz, wx * wz], axis=1)
    return np.concatenate([g - omega2_c, np.zeros_like(omega), omega * omega - spin2, shear], axis=1)
