"""Shared machinery of the motion and physics fast-path tests.

Small configurations and parameters (from tests/ref/motion/cases.py), and the three checks
every fast function gets against its reference twin:
- `check_agreement`: float64 outputs, then float64 gradients of a random cotangent with
  respect to chosen arguments (parameter dicts included), fast (torch autograd) vs
  reference (`autograd`);
- `check_float32`: float32 outputs vs the float64 reference;
- `gradcheck_fn`: torch.autograd.gradcheck of the fast function alone.
Agreement is scale-relative: max |fast - ref| <= rtol * max |ref| per output (and per
gradient leaf), because elementwise relative error is meaningless at entries near zero.
"""

import numpy as np
import torch
from autograd import make_vjp
from autograd.builtins import tuple as ag_tuple
from hypothesis import HealthCheck, settings

# The NumPy-side helpers (configs, parameter dicts, masks) are shared with the reference's
# tests; the fast tests import them from here with the torch-side checks.
from tests.ref.motion.cases import (RIGID_MASK, TRANSLATION_MASK, column_mask,  # noqa: F401
                                    constant_coefficient_params, map_leaves, mlp_velocity_params, random_params,
                                    small_cfg)
from velogauss_fast.motion.params import params_to_torch

# float64 fast vs reference: both evaluate the same formulas in the same order up to a
# few reassociations (a x + b as one sum, BLAS blocking of matrix products), i.e. a few
# ulps of the largest intermediate; 1e-9 leaves 1e5-fold headroom over that and still
# fails any formula error (which shows at 1e-3 or above).
RTOL64 = 1e-9
# float32 fast vs the float64 reference. Calibrated: the observed error of the deepest
# function checked this way (RK4 base_state over 8 steps on the small networks) is below
# 1e-5 relative to the output scale (float32 eps 6e-8 times the condition number of a few
# chained layers and steps); 1e-4 leaves 10x headroom.
RTOL32 = 1e-4

# The `device` fixture is function-scoped but constant per run, which is safe under
# hypothesis; keep the profile's other suppressions.
DEVICE_SETTINGS = settings(
    suppress_health_check=[*settings.default.suppress_health_check, HealthCheck.function_scoped_fixture]
)


def leaves(node):
    """The arrays/tensors of a nested dict/list/tuple in a fixed order."""
    if isinstance(node, dict):
        return [t for k in node for t in leaves(node[k])]
    if isinstance(node, (list, tuple)):
        return [t for v in node for t in leaves(v)]
    return [node]


def rebuild(template, flat):
    """The structure of `template` with its leaves replaced, in order, by `flat`."""
    it = iter(flat)
    return map_leaves(lambda _: next(it), template)


def to_torch(value, dtype, device, requires_grad=False):
    """A NumPy array, parameter dict or float as torch (numbers stay numbers unless requires_grad)."""
    if isinstance(value, dict):
        return params_to_torch(value, dtype, device, requires_grad)
    if isinstance(value, (float, int)) and not requires_grad:
        return value
    return torch.tensor(np.asarray(value, dtype=np.float64), dtype=dtype, device=device,
                        requires_grad=requires_grad)


def to_numpy(x):
    return x.detach().cpu().double().numpy()


def as_tuple(out):
    return out if isinstance(out, tuple) else (out,)


def assert_close(actual, expected, rtol, name=""):
    """max |actual - expected| <= rtol * max |expected| (+ tiny absolute floor for all-zero)."""
    a = to_numpy(actual) if isinstance(actual, torch.Tensor) else np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    assert a.shape == e.shape, f"{name}: shape {a.shape} != {e.shape}"
    if e.size == 0:
        return
    assert np.all(np.isfinite(a)), f"{name}: non-finite values"
    scale = float(np.max(np.abs(e)))
    err = float(np.max(np.abs(a - e)))
    assert err <= rtol * scale + 1e-300, f"{name}: max abs error {err:.3e} > {rtol:.1e} * max|ref| {scale:.3e}"


def check_agreement(ref_fn, fast_fn, args, diff, device, seed=0, rtol=RTOL64, grad_rtol=RTOL64):
    """Fast vs reference in float64: outputs, then gradients w.r.t. args[i] for i in diff.

    args: NumPy arrays, parameter dicts, or static values (floats, configs, strings);
    diff: indices of the arguments to differentiate (a float there becomes a 0-d tensor).
    The gradient is that of <out, c> for a random cotangent c (JAX check_grads style).
    """
    t_args = [to_torch(a, torch.float64, device, requires_grad=i in diff)
              if isinstance(a, (np.ndarray, dict)) or i in diff else a for i, a in enumerate(args)]
    out_f, out_r = as_tuple(fast_fn(*t_args)), as_tuple(ref_fn(*args))
    assert len(out_f) == len(out_r)
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float64 and f.device.type == torch.device(device).type
        assert_close(f, r, rtol, name=f"output {k}")
    if not diff:
        return
    rng = np.random.default_rng(seed)
    cot = tuple(rng.standard_normal(np.shape(r)) for r in out_r)

    def ref_selected(selected):
        full = list(args)
        for i, a in zip(diff, selected):
            full[i] = a
        out = ref_fn(*full)
        # A plain tuple of boxes is invisible to autograd (it would report zero
        # gradients); its own tuple type is traced.
        return ag_tuple(out) if isinstance(out, tuple) else out

    vjp, _ = make_vjp(ref_selected)(tuple(args[i] for i in diff))
    g_ref = leaves(vjp(cot if len(cot) > 1 else cot[0]))
    total = sum((f * torch.as_tensor(c, dtype=f.dtype, device=f.device)).sum() for f, c in zip(out_f, cot))
    wrt = leaves([t_args[i] for i in diff])
    g_fast = torch.autograd.grad(total, wrt, allow_unused=True)
    for k, (gf, gr, w) in enumerate(zip(g_fast, g_ref, wrt)):
        gf = torch.zeros_like(w) if gf is None else gf
        assert_close(gf, np.asarray(gr), grad_rtol, name=f"gradient leaf {k}")


def check_float32(ref_fn, fast_fn, args, device, rtol=RTOL32):
    """Fast in float32 vs the reference in float64."""
    t_args = [to_torch(a, torch.float32, device) if isinstance(a, (np.ndarray, dict)) else a for a in args]
    out_f, out_r = as_tuple(fast_fn(*t_args)), as_tuple(ref_fn(*args))
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float32
        assert_close(f, r, rtol, name=f"float32 output {k}")


def gradcheck_fn(fast_fn, args, diff, device):
    """torch.autograd.gradcheck of fast_fn in float64 w.r.t. args[i], i in diff (dicts flattened)."""
    # A float argument in diff becomes a 0-d tensor (to_torch leaves numbers alone otherwise).
    t_args = [to_torch(a, torch.float64, device, requires_grad=i in diff)
              if isinstance(a, (np.ndarray, dict)) or i in diff else a for i, a in enumerate(args)]
    templates = {i: t_args[i] for i in diff}
    flat, spans = [], {}
    for i in diff:
        ls = [x.detach().clone().requires_grad_() for x in leaves(templates[i])]
        spans[i] = (len(flat), len(flat) + len(ls))
        flat += ls

    def fn(*xs):
        full = list(t_args)
        for i in diff:
            a, b = spans[i]
            full[i] = rebuild(templates[i], xs[a:b]) if isinstance(templates[i], dict) else xs[a]
        return fast_fn(*full)

    # fast_mode: one random projection of the Jacobian, not every column (cost independent of
    # the parameter count), compared between analytic and finite differences.
    assert torch.autograd.gradcheck(fn, tuple(flat), eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)
