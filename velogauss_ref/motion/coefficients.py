"""Basis coefficients w(t, z) = m(z) P(t) from K motion patterns.

spec/motion.md, VG-COEF, VG-COEF-RIGID and VG-COEF-HARM.
"""

import math

import autograd.numpy as np
import numpy as onp

from velogauss_ref.checks import check_array, check_scalar
from velogauss_core.motion import N_BASIS
from velogauss_ref.motion.basis import affine_from_coefficients
from velogauss_ref.nn import mlp, positional_encoding


def coefficients(params, t, z, cfg):
    """w = m(z) P(t), with the columns outside cfg.mask set to zero (VG-COEF).

    params: motion parameter dict (uses "mix" and "time"); t: scalar time, any real value;
    z: (N, L) physics codes; cfg: MotionSpec -> w: (N, 12).
    The time network runs once for this t; particles differ only through m(z), so every
    row of w is a convex combination of the K patterns (before masking).
    A non-finite or non-scalar t, or a z that is non-finite or not L wide (the rows of
    params["mix"]'s A), raise ValueError.
    """
    check_scalar("t", t)
    check_array("z", z, (None, np.shape(params["mix"][0][0])[0]))
    return masked(mixing_weights(params, z) @ motion_patterns(params, t, cfg), cfg.mask)


def mixing_weights(params, z):
    """m(z) = softmax(z A + c): (N, L) codes -> (N, K) weights, each row summing to 1.

    Uses params["mix"] = [(A (L, K), c (K,))]. Each row u is shifted by its maximum first
    (softmax is shift-invariant), so exp cannot overflow however large z A + c grows and
    the weights sum to 1 within a few ulps.
    """
    A, c = params["mix"][0]
    check_array('params["mix"][0][0]', A, (np.shape(z)[1], None))
    check_array('params["mix"][0][1]', c, (np.shape(A)[1],))
    u = np.dot(z, A) + c
    e = np.exp(u - np.max(u, axis=-1, keepdims=True))
    return e / np.sum(e, axis=-1, keepdims=True)


def motion_patterns(params, t, cfg):
    """P(t) = reshape(mlp(params["time"], gamma(t)), (K, 12)): the K motion patterns at t.

    gamma with cfg.n_freqs_t frequencies (0: raw t, which does not repeat periodically
    into the future); K = cfg.n_patterns. The rigid bodies of VG-COEF-RIGID under
    cfg.pattern_form "rigid", the oscillators of VG-COEF-HARM under "harmonic". Under
    cfg.future "coast" a t past cfg.max_time reads P(max_time) (VG-COEF-COAST). The time
    network's and the oscillators' patterns are written about the centres params["centre"]
    (K, 3) when the dict holds them (VG-COEF-CENTRE).
    """
    if cfg.future == "coast":
        t = np.minimum(t, cfg.max_time)
    if cfg.pattern_form == "rigid":
        return rigid_velocity_patterns(params["time"], t, cfg.max_time)
    if cfg.pattern_form == "harmonic":
        return centred(harmonic_velocity_patterns(*params["time"][0], t), params.get("centre"))
    gamma_t = positional_encoding(np.reshape(t, (1,)), cfg.n_freqs_t)
    return centred(np.reshape(mlp(params["time"], gamma_t), (cfg.n_patterns, N_BASIS)), params.get("centre"))


def centred(P, centres):
    """World-frame patterns (K, 12) of patterns P (K, 12) written about their centres (VG-COEF-CENTRE).

    Pattern k's field A_k (x - c_k) + b_k is A_k x + (b_k - A_k c_k): only the translation
    columns change, by -A(P_k) c_k. centres: (K, 3), or None for the world's origin (P as it is).
    """
    if centres is None:
        return P
    check_array("centres", centres, (np.shape(P)[0], 3))
    A, b = affine_from_coefficients(P)
    shift = np.sum(A * centres[:, None, :], axis=-1)  # A_k c_k, (K, 3)
    return np.concatenate([b - shift, P[:, 3:]], axis=1)


def rigid_velocity_patterns(B, t, max_time):
    """P(t) (K, 12) of K rigid bodies (VG-COEF-RIGID).

    B: (K, 3 + 3 n), each row (omega, c(tau_1), ..., c(tau_n)): a constant spin and the
    body's centre at n = 2 or 3 knots tau evenly spaced over [0, max_time]; scalar t. The
    centre c(t) is the polynomial through the knots (Lagrange form: a line for 2 knots, a
    parabola for 3), and the body's velocity field v = omega x (x - c(t)) + c'(t) has the
    coefficients [c'(t) - omega x c(t) | omega | 0 (stretch) | 0 (shear)].
    """
    check_array("B", B, (None, None))
    check_scalar("t", t)
    check_scalar("max_time", max_time)
    n = (np.shape(B)[1] - 3) // 3
    if np.shape(B)[1] != 3 + 3 * n or n not in (2, 3):
        raise ValueError(f"B: expected 9 or 12 columns (a spin and 2 or 3 knots), got {np.shape(B)[1]}")
    omega = B[:, 0:3]
    nodes = [max_time * i / (n - 1) for i in range(n)]
    c, c_dot = 0.0, 0.0
    for i, node in enumerate(nodes):
        knot = B[:, 3 + 3 * i:6 + 3 * i]
        others = nodes[:i] + nodes[i + 1:]
        scale = math.prod(node - o for o in others)
        # l_i(t) = prod_j (t - tau_j) / scale; its derivative sums the products leaving one out
        # (math.prod multiplies autograd's traced t as it is).
        c = c + knot * (math.prod(t - o for o in others) / scale)
        c_dot = c_dot + knot * (sum(math.prod(t - o for k, o in enumerate(others) if k != j)
                                    for j in range(len(others))) / scale)
    translation = c_dot - np.cross(omega, c)
    return np.concatenate([translation, omega, np.zeros((np.shape(B)[0], 6))], axis=1)


def harmonic_velocity_patterns(C, omega, t):
    """P(t) (K, 12) of K oscillators sharing one frequency (VG-COEF-HARM).

    C: (3, K, 12), the blocks (a, b, c) of 12 basis coefficients per pattern; omega: (1,), the
    frequency in radians per unit time; scalar t. P_k(t) = a_k + b_k cos(Omega t) + c_k
    sin(Omega t): every pattern's velocity oscillates about its mean a_k, and keeps doing so
    past the observed window. A mixture of them is again such an oscillator.
    """
    check_array("C", C, (3, None, N_BASIS))
    check_array("omega", omega, (1,))
    check_scalar("t", t)
    theta = omega[0] * t
    return C[0] + C[1] * np.cos(theta) + C[2] * np.sin(theta)


def masked(w, mask):
    """w (..., 12) with the columns where mask (12 bools, or None for all) is False set to 0."""
    if mask is None:
        return w
    return w * onp.asarray(mask, dtype=float)
