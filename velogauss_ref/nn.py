"""Positional encoding and plain MLPs whose parameters are explicit (W, b) lists.

spec/motion.md, VG-ENC and VG-MLP.
"""

import autograd.numpy as np
import numpy as onp
from autograd.scipy.special import expit

from velogauss_ref.checks import check_array


def positional_encoding(x, n_freqs):
    """gamma(x) = [x, sin(2^0 pi x), cos(2^0 pi x), ..., sin(2^(n-1) pi x), cos(2^(n-1) pi x)] (VG-ENC).

    x: (..., D) -> (..., D (1 + 2 n_freqs)), concatenated in that order, each block D wide;
    n_freqs = 0 returns x itself. A negative or non-integer n_freqs, non-finite or 0-d x
    raise ValueError.
    """
    check_array("x", x, ("...", None))
    if isinstance(n_freqs, (bool, onp.bool_)) or not isinstance(n_freqs, (int, onp.integer)) or n_freqs < 0:
        raise ValueError(f"n_freqs: expected a non-negative int, got {n_freqs!r}")
    blocks = [x]
    for k in range(n_freqs):
        angle = 2.0**k * (np.pi * x)
        blocks += [np.sin(angle), np.cos(angle)]
    return np.concatenate(blocks, axis=-1)


def mlp(layers, x):
    """y = MLP(x): h <- silu(h W_k + b_k) for every layer but the last, which is linear (VG-MLP).

    layers: non-empty list of (W_k (d_k, d_k+1), b_k (d_k+1,)); x: (..., d_0) -> (..., d_L).
    Empty layers, a W whose rows do not match the previous layer's outputs, or bad x raise
    ValueError naming the entry (`layers[k].W`, `layers[k].b`, `x`).
    """
    if not layers:
        raise ValueError("layers: expected at least one (W, b) pair, got none")
    for k, (W, b) in enumerate(layers):
        check_array(f"layers[{k}].W", W, (None, None))
        check_array(f"layers[{k}].b", b, (np.shape(W)[1],))
        if k > 0 and np.shape(W)[0] != np.shape(layers[k - 1][0])[1]:
            rows = np.shape(layers[k - 1][0])[1]
            raise ValueError(f"layers[{k}].W: expected {rows} input rows, got {np.shape(W)[0]}")
    check_array("x", x, ("...", np.shape(layers[0][0])[0]))
    h = x
    for W, b in layers[:-1]:
        h = silu(np.dot(h, W) + b)
    W, b = layers[-1]
    return np.dot(h, W) + b


def silu(u):
    """silu(u) = u sigmoid(u), elementwise.

    The logistic is scipy's expit, exact for any u: a literal 1 / (1 + exp(-u)) overflows
    for u < -709 and its autograd derivative is then inf / inf = NaN.
    """
    return u * expit(u)
