"""Validation of scalar times for the torch motion model (spec/conventions.md, "Bad input").

Times are python numbers or 0-d tensors (a tensor time may carry gradients, e.g. for
d v / d t). `velogauss_fast.checks` has no scalar check, and the reference's
`check_scalar` goes through NumPy, which a tensor that requires grad or lives on CUDA
cannot do.
"""

import math
import numbers

import torch


def check_time(name, t):
    """Raise ValueError unless `t` is a finite real number or a 0-d float tensor; return it.

    A number's finiteness costs nothing to test; a tensor's would be a device sync, so, as
    for `velogauss_fast.checks.check_array`, only its shape and dtype are checked here and
    its values where it enters (`velogauss_fast.checks.check_finite`, in the model).
    """
    if isinstance(t, torch.Tensor):
        if t.dim() != 0 or not t.is_floating_point():
            raise ValueError(f"{name}: expected a finite real scalar, got a tensor of shape "
                             f"{tuple(t.shape)} and dtype {t.dtype}")
        return t
    if isinstance(t, bool) or not isinstance(t, numbers.Real) or not math.isfinite(t):
        raise ValueError(f"{name}: expected a finite real scalar, got {t!r}")
    return t


def time_tensor(t, like):
    """`t` as a (1,) tensor with the dtype and device of `like`, keeping any autograd graph."""
    if isinstance(t, torch.Tensor):
        return t.to(dtype=like.dtype, device=like.device).reshape(1)
    return torch.full((1,), float(t), dtype=like.dtype, device=like.device)


def times_tensor(times, like):
    """A list of scalar times (numbers or 0-d tensors) as one (S,) tensor with the dtype and
    device of `like`, keeping the autograd graph of tensor entries."""
    if any(isinstance(t, torch.Tensor) for t in times):
        return torch.cat([time_tensor(t, like) for t in times])
    return torch.tensor([float(t) for t in times], dtype=like.dtype, device=like.device)
