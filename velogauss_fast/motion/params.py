"""The motion parameter dict in torch: drawn fresh, or converted from NumPy arrays.

The motion parameters (spec/motion.md, "Parameters and configuration") are one dict of
lists of (W, b) pairs plus the acceleration array "acc"; the fast path uses the same
structure with tensors in place of NumPy arrays.
"""

import functools
import math

import numpy as np
import torch

from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_core.motion import N_BASIS, MotionConfig, network_shapes


def params_to_torch(params_np, dtype, device, requires_grad=False):
    """The same nested dict/list/tuple structure with every array as a tensor.

    params_np: dict of NumPy arrays in the layout of `init_motion_params`; dtype:
    torch.float32 or torch.float64; device: any torch device. Every leaf becomes a fresh
    leaf tensor (requiring grad when requires_grad is True). Raises ValueError naming the
    offending entry for a non-numeric or non-finite leaf.
    """
    if dtype not in (torch.float32, torch.float64):
        raise ValueError(f"dtype: expected torch.float32 or torch.float64, got {dtype!r}")
    return _convert(params_np, "params_np", dtype, torch.device(device), requires_grad)


def _convert(node, name, dtype, device, requires_grad):
    if isinstance(node, dict):
        return {k: _convert(v, f"{name}[{k!r}]", dtype, device, requires_grad) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        items = [_convert(v, f"{name}[{i}]", dtype, device, requires_grad) for i, v in enumerate(node)]
        return type(node)(items)
    value = np.asarray(node)
    if value.dtype.kind not in "biuf" or not np.all(np.isfinite(value)):
        raise ValueError(f"{name}: expected a finite real array")
    return torch.tensor(value, dtype=dtype, device=device, requires_grad=requires_grad)


def init_motion_params(cfg: MotionConfig, generator: torch.Generator | None = None, dtype: torch.dtype = torch.float32,
                       device: torch.device | str = "cpu") -> dict:
    """A fresh parameter dict for `cfg`, drawn with torch. Twin of
    `velogauss_ref.motion.config.init_motion_params` (spec/motion.md, "Parameters and configuration").

    Same layout, sizes and distributions as the reference (values differ: torch's random
    stream, not NumPy's): hidden layers PyTorch-Linear initialised (uniform within
    +-1/sqrt(fan_in)), the mixing matrix A standard normal / sqrt(L), and zero heads for the
    time network, Q and the ADF, so a fresh model is the still canonical scene. Leaves are
    plain tensors (no grad); `generator` makes the draws reproducible.
    """
    L, K = cfg.code_dim, cfg.n_patterns
    shapes = network_shapes(cfg)
    new = functools.partial(torch.empty, dtype=dtype, device=device)

    def mlp(key, zero_last=False):
        return mlp_layers(*shapes[key], cfg.hidden, cfg.depth, generator, dtype, device, zero_last)

    return {
        "code": mlp("code"),
        "mix": [(new(L, K).normal_(generator=generator) / math.sqrt(L), new(K).zero_())],
        "time": mlp("time", zero_last=True),
        "acc": new(ACC_POLY_DEGREE + 1, K, N_BASIS).zero_(),
        "adf": mlp("adf", zero_last=True),
    }


def mlp_layers(d_in: int, d_out: int, hidden: int, depth: int, generator: torch.Generator | None = None,
               dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu",
               zero_last: bool = False) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Layers (W (d_in, d_out), b (d_out,)) of an MLP d_in -> hidden^depth -> d_out with
    PyTorch's Linear initialisation (uniform within +-1/sqrt(fan_in)); the last layer is
    zero when `zero_last` (a head that starts still)."""
    dims = [d_in] + [hidden] * depth + [d_out]
    layers = []
    for k, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        W, bias = torch.empty(a, b, dtype=dtype, device=device), torch.empty(b, dtype=dtype, device=device)
        if zero_last and k == len(dims) - 2:
            layers.append((W.zero_(), bias.zero_()))
        else:
            bound = 1.0 / math.sqrt(a)
            layers.append((W.uniform_(-bound, bound, generator=generator), bias.uniform_(-bound, bound, generator=generator)))
    return layers
