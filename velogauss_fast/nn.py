"""Positional encoding and plain MLPs, in torch.

Twin of `velogauss_ref.nn` (spec/motion.md, VG-ENC and VG-MLP). Their checks read shapes
and dtypes only (`velogauss_fast.checks.check_array`), so the motion calls them everywhere,
under `torch.func.jvp`/`vmap` too. `positional_encoding_jet` and `mlp_jet` add their
forward-mode derivatives, written out for these known layer structures (the physics
residuals' grad v and dv/dt; their reference is the reference's reverse-mode autograd).
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
    freqs = _frequencies(x, n_freqs)
    if n_freqs == 0:
        return x
    angles = x[..., None, :] * freqs[:, None]  # [..., n_freqs, D]
    sincos = torch.stack([torch.sin(angles), torch.cos(angles)], dim=-2)  # [..., n_freqs, 2, D]
    return torch.cat([x, sincos.flatten(-3)], dim=-1)


def positional_encoding_jet(x, n_freqs):
    """(gamma(x), d gamma / d x) of VG-ENC, from one evaluation of the sines and cosines.

    x: (..., D); n_freqs: non-negative int -> gamma: (..., E) as `positional_encoding`,
    E = D (1 + 2 n_freqs); J: (D, ..., E) with J[j] = d gamma / d x_j. Column c of gamma
    depends on x_(c mod D) alone, so J[j] holds that one derivative where c mod D = j.
    """
    freqs = _frequencies(x, n_freqs)
    D = x.shape[-1]
    angles = x[..., None, :] * freqs[:, None]  # [..., n_freqs, D]
    sin, cos = torch.sin(angles), torch.cos(angles)
    gamma = torch.cat([x, torch.stack([sin, cos], dim=-2).flatten(-3)], dim=-1)  # [..., E]
    f = freqs[:, None]
    d_own = torch.cat([torch.ones_like(x), torch.stack([f * cos, -f * sin], dim=-2).flatten(-3)], dim=-1)  # [..., E]
    axis_of_column = torch.arange(gamma.shape[-1], device=x.device) % D
    owner = (axis_of_column == torch.arange(D, device=x.device)[:, None]).to(x.dtype)  # [D, E]
    return gamma, d_own * owner.reshape((D,) + (1,) * (x.dim() - 1) + (-1,))


def mlp_jet(layers, x, dx):
    """(MLP(x), its directional derivatives along the tangents dx) of VG-MLP, in one pass.

    layers: as `mlp`; x: (..., d_0); dx: (T, ..., d_0), T tangents of every input row ->
    y: (..., d_L) (the same operations as `mlp`, so the same values), dy: (T, ..., d_L)
    with dy[k] = (d MLP / d x) dx[k]. Forward mode by hand: each hidden layer maps the
    tangents by W and scales them by silu'(u) = s (1 + u (1 - s)), s the logistic of the
    pre-activation u. The tangent axis leads, so that scaling broadcasts over whole
    contiguous (..., d) blocks. Built of plain differentiable ops: reverse mode runs through it (the physics loss
    backpropagates to the weights and to x).
    """
    _check_layers(layers)
    check_array("x", x, ("...", layers[0][0].shape[0]))
    check_array("dx", dx, (None,) + tuple(x.shape))
    h, dh = x, dx
    for W, b in layers[:-1]:
        u = h @ W + b
        s = torch.sigmoid(u)
        h = F.silu(u)
        dh = (dh @ W) * (s * (1 + u * (1 - s)))
    W, b = layers[-1]
    return h @ W + b, dh @ W


def mlp(layers, x):
    """y = MLP(x) with silu between layers and a linear last layer (VG-MLP).

    layers: non-empty list of (W (d_k, d_k+1), b (d_k+1,)); x: (..., d_0) -> (..., d_L).
    """
    _check_layers(layers)
    check_array("x", x, ("...", layers[0][0].shape[0]))
    h = x
    for W, b in layers[:-1]:
        h = F.silu(h @ W + b)
    W, b = layers[-1]
    return h @ W + b


def _frequencies(x, n_freqs):
    """The (n_freqs,) tensor 2^k pi of VG-ENC, dtype and device of x, after checking x and n_freqs."""
    check_array("x", x, ("...", None))
    if isinstance(n_freqs, bool) or not isinstance(n_freqs, int) or n_freqs < 0:
        raise ValueError(f"n_freqs: expected a non-negative int, got {n_freqs!r}")
    # 2^k pi is exact times pi, so (2^k pi) x rounds exactly like the reference's 2^k (pi x).
    return torch.tensor([2.0**k * math.pi for k in range(n_freqs)], dtype=x.dtype, device=x.device)


def _check_layers(layers):
    """Raise ValueError unless `layers` is a non-empty chain of (W (d_k, d_k+1), b (d_k+1,))."""
    if not layers:
        raise ValueError("layers: expected at least one (W, b) pair, got none")
    for k, (W, b) in enumerate(layers):
        check_array(f"layers[{k}].W", W, (None, None))
        check_array(f"layers[{k}].b", b, (W.shape[1],))
        if k > 0 and W.shape[0] != layers[k - 1][0].shape[1]:
            raise ValueError(
                f"layers[{k}].W: expected {layers[k - 1][0].shape[1]} input rows, got {W.shape[0]}"
            )
