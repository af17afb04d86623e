"""Input validation for the torch fast path (spec/conventions.md, "Bad input").

The twin of `velogauss_core.checks.check_array` for tensors: bad input raises ValueError whose message
starts with the argument's name. Checks run on the tensor's own device (no host copy of
the data, one device sync for the finiteness flag) and never touch autograd.
"""

import torch

from velogauss_core.checks import format_shape, shape_matches


def check_array(name, x, shape=None):
    """Raise ValueError unless `x` is a finite real floating tensor matching `shape`.

    `shape` is a `velogauss_core.checks.Shape`: a tuple of ints (exact size), None
    (any size) and optionally "..." first (any leading batch dimensions).
    Returns `x` unchanged so calls can be chained.
    """
    if not isinstance(x, torch.Tensor):
        raise ValueError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if shape is not None and not shape_matches(tuple(x.shape), shape):
        raise ValueError(f"{name}: expected shape {format_shape(shape)}, got {tuple(x.shape)}")
    if not x.is_floating_point():
        raise ValueError(f"{name}: expected a floating-point tensor, got dtype {x.dtype}")
    # x * 0 is 0 where x is finite and NaN where it is inf or NaN, so one product and one
    # sum (exact: a sum of zeros) test every entry; on big inputs that is several times
    # cheaper than isfinite().all(), whose comparisons run once per input of each call.
    if bool(torch.isnan((x.detach() * 0).sum())):
        bad = int((~torch.isfinite(x.detach())).sum())
        raise ValueError(f"{name}: contains {bad} non-finite value(s) (NaN or inf)")
    return x

