"""Input validation for the torch fast path (spec/conventions.md, "Bad input").

Two checks, both raising ValueError whose message starts with the argument's name:

- `check_array`: type, shape and floating dtype, read from the tensor's metadata alone. The
  spec functions of `velogauss_fast` (the twins of `velogauss_ref`'s) run it on their
  tensor arguments; it never reads the data, so it costs no device sync and works on the
  wrapped tensors of `torch.func.jvp`/`vmap`.
- `check_finite`: NaN and inf, which needs the data: one host read of a flag computed on
  the tensors' device (a device sync on CUDA). It runs only where data enters, gsplat's
  way: `velogauss_fast.rasterize`, the model (`velogauss.model.velogauss_model`); the data
  loaders check their NumPy arrays with `velogauss_core.checks`. Inner functions trust their
  callers.
"""

import numpy as np
import torch

from velogauss_core.checks import format_shape, shape_matches


def check_array(name, x, shape=None):
    """Raise ValueError unless `x` is a real floating tensor matching `shape`; return `x`.

    `shape` is a `velogauss_core.checks.Shape`: a tuple of ints (exact size), None
    (any size) and optionally "..." first (any leading batch dimensions). The values are
    not read (see `check_finite`).
    """
    if not isinstance(x, torch.Tensor):
        raise ValueError(f"{name}: expected a torch.Tensor, got {type(x).__name__}")
    if shape is not None and not shape_matches(tuple(x.shape), shape):
        raise ValueError(f"{name}: expected shape {format_shape(shape)}, got {tuple(x.shape)}")
    if not x.is_floating_point():
        raise ValueError(f"{name}: expected a floating-point tensor, got dtype {x.dtype}")
    return x


def check_finite(**tensors):
    """Raise ValueError naming the first of `tensors` (name=tensor, floating tensors on one
    device, already through `check_array`) that holds a NaN or an inf.

    One host read for all of them, whatever their number: the device sync of a boundary.
    """
    # x * 0 is 0 where x is finite and NaN where it is inf or NaN, so one product and one
    # sum (exact: a sum of zeros) test every entry; on big inputs that is several times
    # cheaper than isfinite().all(), whose comparisons run once per input of each call.
    if all(x.device.type == "cpu" and x.dtype != torch.bfloat16 for x in tensors.values()):
        # On the CPU in NumPy, on the calling thread: torch's reductions open OpenMP regions whose
        # workers spin against a busy process beside a library user's script (RESULTS.md,
        # "Library use"). inf * 0 is the NaN looked for, not a warning.
        with np.errstate(invalid="ignore"):
            flags = [bool(np.isnan((x.detach().numpy() * 0).sum())) for x in tensors.values()]
        if not any(flags):
            return
    else:
        flags = torch.stack([(x.detach() * 0).sum().isnan() for x in tensors.values()])
        if not bool(flags.any()):
            return
        flags = flags.tolist()
    name, x = next((name, x) for (name, x), bad in zip(tensors.items(), flags) if bad)
    bad = int((~torch.isfinite(x.detach())).sum())
    raise ValueError(f"{name}: contains {bad} non-finite value(s) (NaN or inf)")
