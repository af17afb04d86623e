"""Basis coefficients w(t, z) = m(z) P(t) from K motion patterns.

spec/motion.md, VG-COEF.
"""

import autograd.numpy as np
import numpy as onp

from velogauss_ref.checks import check_array, check_scalar
from velogauss_core.motion import N_BASIS
from velogauss_ref.nn import mlp, positional_encoding


def coefficients(params, t, z, cfg):
    """w = m(z) P(t), with the columns outside cfg.mask set to zero (VG-COEF).

    params: motion parameter dict (uses "mix" and "time"); t: scalar time, any real value;
    z: (N, L) physics codes; cfg: MotionConfig -> w: (N, 12).
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
    into the future); K = cfg.n_patterns.
    """
    gamma_t = positional_encoding(np.reshape(t, (1,)), cfg.n_freqs_t)
    return np.reshape(mlp(params["time"], gamma_t), (cfg.n_patterns, N_BASIS))


def masked(w, mask):
    """w (..., 12) with the columns where mask (12 bools, or None for all) is False set to 0."""
    if mask is None:
        return w
    return w * onp.asarray(mask, dtype=float)
