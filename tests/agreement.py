"""The one harness of the ref-vs-fast agreement tests (tests/fast/motion/cases.py and
tests/fast/render_cases.py add their own inputs on top of it).

- `check_agreement`: fast (torch, float64) vs reference (NumPy): outputs, then gradients of
  <out, c> for a random cotangent c, torch autograd vs the reference's `autograd`, with
  respect to chosen arguments (parameter dicts included);
- `check_float32`: fast in float32 vs the float64 reference;
- `gradcheck_fn`: torch.autograd.gradcheck of the fast function alone.
Agreement is scale-relative: max |fast - ref| <= rtol * max |ref| per output (and per
gradient leaf), because an elementwise relative error is meaningless at entries near zero.
"""

import numpy as np
import torch
from autograd import make_vjp
from autograd.builtins import tuple as ag_tuple
from hypothesis import HealthCheck, settings

from tests.ref.motion.cases import map_leaves
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
# Two float64 backward passes on CUDA may differ: index_add_ (velogauss_fast/composite.py)
# adds with atomics in a varying order, i.e. float64 rounding of ~1e-16 relative to sums of
# order 1. gradcheck's reentrancy check asks them to agree to this; it sits a million times
# under the gradient check's own atol of 1e-6, so it hides no gradient error. (The first GPU
# run failed the rasterizer's gradcheck only on this, with analytic = numerical gradients.)
NONDET_TOL_CUDA = 1e-12

# The `device` fixture is function-scoped but constant per run, which is safe under
# hypothesis; keep the profile's other suppressions.
DEVICE_SETTINGS = settings(
    suppress_health_check=[*settings.default.suppress_health_check, HealthCheck.function_scoped_fixture]
)


def to_torch(value, dtype=torch.float64, device="cpu", requires_grad=False):
    """An array (or nested list), parameter dict or number as torch; numbers stay numbers
    unless requires_grad."""
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


def assert_close(actual, expected, rtol, name="", mask=None, floor=0.0):
    """max |actual - expected| <= rtol * max(max |expected|, floor) over `mask` (all if None).

    `floor` is the scale below which values count as zero (gradients that vanish
    identically come out as rounding noise of ~1e-16 in both implementations); an
    all-zero reference asks for an error below 1e-300.
    """
    a = to_numpy(actual) if isinstance(actual, torch.Tensor) else np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    assert a.shape == e.shape, f"{name}: shape {a.shape} != {e.shape}"
    assert np.all(np.isfinite(a)), f"{name}: non-finite values"
    if mask is not None:
        a, e = a[mask], e[mask]
    if e.size == 0:
        return
    scale = max(float(np.max(np.abs(e))), floor)
    err = float(np.max(np.abs(a - e)))
    assert err <= rtol * scale + 1e-300, f"{name}: max abs error {err:.3e} > {rtol:.1e} * max|ref| {scale:.3e}"


def _torch_args(args, dtype, device, diff=()):
    # A float argument in diff becomes a 0-d tensor (to_torch leaves numbers alone otherwise).
    return [to_torch(a, dtype, device, requires_grad=i in diff)
            if isinstance(a, (np.ndarray, dict)) or i in diff else a for i, a in enumerate(args)]


def check_agreement(ref_fn, fast_fn, args, diff, device, seed=0, rtol=RTOL64, grad_rtol=RTOL64, floor=0.0,
                    grad_floor=0.0):
    """Fast vs reference in float64: outputs, then gradients w.r.t. args[i] for i in diff.

    args: NumPy arrays, parameter dicts, or static values (floats, configs, strings);
    diff: indices of the arguments to differentiate (a float there becomes a 0-d tensor).
    The gradient is that of <out, c> for a random cotangent c (JAX check_grads style).
    floor, grad_floor: the output and gradient scales below which values count as zero
    (`assert_close`).
    """
    t_args = _torch_args(args, torch.float64, device, diff)
    out_f, out_r = as_tuple(fast_fn(*t_args)), as_tuple(ref_fn(*args))
    assert len(out_f) == len(out_r)
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float64 and f.device.type == torch.device(device).type
        assert_close(f, r, rtol, name=f"output {k}", floor=floor)
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
        assert_close(gf, np.asarray(gr), grad_rtol, name=f"gradient leaf {k}", floor=grad_floor)


def check_float32(ref_fn, fast_fn, args, device, rtol=RTOL32, floor=0.0):
    """Fast in float32 vs the reference in float64 (outputs only; floor as in check_agreement).

    The floor is at least float32's smallest normal number over rtol: values below it are
    zero or denormal in float32 (a scale of 1e-89 squares to 0), so only an absolute error
    of that size is asked of them.
    """
    floor = max(floor, float(np.finfo(np.float32).tiny) / rtol)
    t_args = _torch_args(args, torch.float32, device)
    out_f, out_r = as_tuple(fast_fn(*t_args)), as_tuple(ref_fn(*args))
    for k, (f, r) in enumerate(zip(out_f, out_r)):
        assert f.dtype == torch.float32
        assert_close(f, r, rtol, name=f"float32 output {k}", floor=floor)


def gradcheck_fn(fast_fn, args, diff, device, fast_mode=True, atol=1e-5, rtol=1e-4):
    """torch.autograd.gradcheck of fast_fn in float64 w.r.t. args[i], i in diff (dicts flattened).

    Callers keep the inputs away from every threshold of fast_fn (clamps, culling, skips):
    finite differences step 1e-6 across them. fast_mode checks one random projection
    <u, J v> instead of every column (cost independent of the parameter count).
    """
    t_args = _torch_args(args, torch.float64, device, diff)
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

    nondet_tol = NONDET_TOL_CUDA if torch.device(device).type == "cuda" else 0.0
    assert torch.autograd.gradcheck(fn, tuple(flat), eps=1e-6, atol=atol, rtol=rtol, fast_mode=fast_mode,
                                    nondet_tol=nondet_tol)
