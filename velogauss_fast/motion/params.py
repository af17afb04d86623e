"""The motion parameter dict in torch: converted from the NumPy arrays of `init_motion_params`.

The motion parameters (spec/motion.md, "Parameters and configuration") are one dict of
lists of (W, b) pairs plus the acceleration array "acc"; the fast path uses the same
structure with tensors in place of NumPy arrays.
"""

import numpy as np
import torch


def params_to_torch(params_np, dtype, device, requires_grad=False):
    """The same nested dict/list/tuple structure with every array as a tensor.

    params_np: dict of NumPy arrays as `velogauss_core.motion.init_motion_params` draws them; dtype:
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

