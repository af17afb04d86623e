"""Basis coefficients w(t, z) from K motion patterns, in torch.

Twin of `velogauss_ref.motion.coefficients` (spec/motion.md, VG-COEF). The time network
runs once per time for all K patterns; particles differ only through their mixing weights.
"""

import numpy as np
import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import _encode, _mlp


def coefficients(params, t, z, cfg):
    """w = m(z) P(t), masked by cfg.mask (VG-COEF).

    params: motion parameter dict (uses "mix" and "time"); t: scalar time (number or 0-d
    tensor, any real value); z: (N, L) physics codes; cfg: MotionConfig -> w: (N, 12).
    m(z) = softmax(z A + c) (N, K); P(t) = mlp(time, gamma(t)) reshaped (K, 12), evaluated once.
    """
    check_time("t", t)
    check_array("z", z, (None, params["mix"][0][0].shape[0]))
    return _coefficients(params, t, z, cfg)


def _coefficients(params, t, z, cfg):
    return _masked(_mixing(params, z) @ _patterns(params, t, cfg), cfg)


def _mixing(params, z):
    A, c = params["mix"][0]
    return torch.softmax(z @ A + c, dim=-1)  # [N, K]


def _patterns(params, t, cfg):
    W0 = params["time"][0][0]
    out = _mlp(params["time"], _encode(time_tensor(t, W0), cfg.n_freqs_t))  # [K * 12]
    return out.reshape(-1, 12)  # [K, 12]


def _masked(w, cfg):
    """w with the columns outside cfg.mask set to exactly zero (identity when mask is None)."""
    if cfg.mask is None:
        return w
    mask = torch.as_tensor(np.asarray(cfg.mask, dtype=bool), device=w.device)
    return w * mask.to(w.dtype)
