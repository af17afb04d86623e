"""Positional encoding and plain MLPs, in torch.

Twin of `velogauss_ref.nn` (spec/motion.md, VG-ENC and VG-MLP). Their checks read shapes
and dtypes only (`velogauss_fast.checks.check_array`), so the motion calls them everywhere,
under `torch.func.jvp`/`vmap` too.
"""

import math

import torch
import torch.nn.functional as F

from velogauss_fast.checks import check_array


def positional_encoding(x, n_freqs):
    """gamma(x) = [x, sin(2^0 pi x), cos(2^0 pi x), ..., cos(2^(n-1) pi x)] (VG-ENC).

    x: (..., D) -> (..., D (1 + 2 n_freqs)), blocks D wide in that order; n_freqs = 0
    returns x itself. n_freqs must be a non-negative int.
    """
    check_array("x", x, ("...", None))
    if isinstance(n_freqs, bool) or not isinstance(n_freqs, int) or n_freqs < 0:
        raise ValueError(f"n_freqs: expected a non-negative int, got {n_freqs!r}")
    if n_freqs == 0:
        return x
    # 2^k pi is exact times pi, so (2^k pi) x rounds exactly like the reference's 2^k (pi x).
    freqs = torch.tensor([2.0**k * math.pi for k in range(n_freqs)], dtype=x.dtype, device=x.device)
    angles = x[..., None, :] * freqs[:, None]  # [..., n_freqs, D]
    sincos = torch.stack([torch.sin(angles), torch.cos(angles)], dim=-2)  # [..., n_freqs, 2, D]
    return torch.cat([x, sincos.flatten(-3)], dim=-1)


def mlp(layers, x):
    """y = MLP(x) with silu between layers and a linear last layer (VG-MLP).

    layers: non-empty list of (W (d_k, d_k+1), b (d_k+1,)); x: (..., d_0) -> (..., d_L).
    """
    if not layers:
        raise ValueError("layers: expected at least one (W, b) pair, got none")
    for k, (W, b) in enumerate(layers):
        check_array(f"layers[{k}].W", W, (None, None))
        check_array(f"layers[{k}].b", b, (W.shape[1],))
        if k > 0 and W.shape[0] != layers[k - 1][0].shape[1]:
            raise ValueError(
                f"layers[{k}].W: expected {layers[k - 1][0].shape[1]} input rows, got {W.shape[0]}"
            )
    check_array("x", x, ("...", layers[0][0].shape[0]))
    h = x
    for W, b in layers[:-1]:
        h = F.silu(h @ W + b)
    W, b = layers[-1]
    return h @ W + b
