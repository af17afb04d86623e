"""Basis coefficients w(t, z) from K motion patterns, in torch.

Twin of `velogauss_ref.motion.coefficients` (spec/motion.md, VG-COEF). The time network
runs once per time for all K patterns; particles differ only through their mixing weights.
"""

import numpy as np
import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import mlp, positional_encoding


def coefficients(params, t, z, cfg):
    """w = m(z) P(t), masked by cfg.mask (VG-COEF).

    params: motion parameter dict (uses "mix" and "time"); t: scalar time (number or 0-d
    tensor, any real value); z: (N, L) physics codes; cfg: MotionConfig -> w: (N, 12).
    m(z) = softmax(z A + c) (N, K); P(t) = mlp(time, gamma(t)) reshaped (K, 12), evaluated once.
    """
    check_time("t", t)
    check_array("z", z, (None, params["mix"][0][0].shape[0]))
    return masked(mixing_weights(params, z) @ motion_patterns(params, t, cfg), cfg.mask)


def mixing_weights(params, z):
    """m(z) = softmax(z A + c): (N, L) codes -> (N, K) weights (VG-COEF). Unchecked: callers
    (`coefficients`, the trajectory, the residuals) have validated z."""
    A, c = params["mix"][0]
    return torch.softmax(z @ A + c, dim=-1)  # [N, K]


def mixing_weights_jet(params, z, dz):
    """(m(z), its directional derivatives along the tangents dz) (VG-COEF), by hand.

    z: (N, L) codes; dz: (T, N, L) -> m: (N, K) as `mixing_weights`, dm: (T, N, K), from the
    softmax's derivative dm = m (dl - <m, dl>) with dl = dz A the tangents of the logits.
    Unchecked, as `mixing_weights`.
    """
    A, _ = params["mix"][0]
    m = mixing_weights(params, z)
    dl = dz @ A  # [T, N, K]
    return m, m * (dl - (m * dl).sum(-1, keepdim=True))


def motion_patterns(params, t, cfg):
    """P(t) (K, 12): the K motion patterns at the scalar time t (VG-COEF). Unchecked."""
    return motion_patterns_at(params, time_tensor(t, params["time"][0][0]), cfg)[0]  # [K, 12]


def motion_patterns_at(params, times, cfg):
    """P(t) (S, K, 12) at the times (S,) tensor: the time network run once on all of them."""
    out = mlp(params["time"], positional_encoding(times[:, None], cfg.n_freqs_t))  # [S, K * 12]
    return out.reshape(times.shape[0], -1, 12)


def masked(w, mask):
    """w (..., 12) with the columns outside `mask` (cfg.mask or cfg.acc_mask) set to exactly
    zero (identity when mask is None). Unchecked."""
    if mask is None:
        return w
    mask = torch.as_tensor(np.asarray(mask, dtype=bool), device=w.device)
    return w * mask.to(w.dtype)
