"""Gradient check for the reference: autograd's VJP against finite differences.

JAX check_grads style: one random unit direction v over the inputs and one random
cotangent w over the output, so a check costs one VJP and four forward passes however
large the inputs are. Inputs must keep away from thresholds (clamps, culling, skips):
the finite differences sample the segment x +- STEP v.
"""

import numpy as onp
from autograd import make_vjp

# Central differences at steps h and h/2 combined by Richardson extrapolation, which
# cancels the h^2 term: truncation error ~ h^4 |f^(5)| (relative 1e-12 even where an
# input is amplified 1e3-fold, as Sigma -> conic is) and rounding error ~ 1e-16 |f| / h
# ~ 1e-10 for O(1) values; both far below RTOL (float64 throughout). Plain central
# differences at h = 1e-6 miss RTOL on the conic by their h^2 term alone.
STEP = 1e-6
# Relative agreement asked of every gradient of velogauss_ref.
RTOL = 1e-6


def check_grads_fd(f, args, argnums, rng, step=STEP, rtol=RTOL):
    """Assert <w, J v> (finite differences) == <J^T w, v> (autograd) to `rtol`.

    f(*args) -> one float array; J is the Jacobian w.r.t. args[k], k in argnums, jointly;
    rng draws the direction v (unit norm over all selected inputs) and the cotangent w.
    """

    def f_selected(xs):
        full = list(args)
        for k, x in zip(argnums, xs):
            full[k] = x
        return f(*full)

    x0 = tuple(onp.asarray(args[k], dtype=onp.float64) for k in argnums)
    vjp, y = make_vjp(f_selected)(x0)
    w = rng.standard_normal(onp.shape(y))
    v = [rng.standard_normal(x.shape) for x in x0]
    norm = onp.sqrt(sum(onp.sum(vi * vi) for vi in v))
    v = [vi / norm for vi in v]

    def central_difference(h):
        plus = f_selected(tuple(x + h * vi for x, vi in zip(x0, v)))
        minus = f_selected(tuple(x - h * vi for x, vi in zip(x0, v)))
        return onp.sum(w * (onp.asarray(plus) - onp.asarray(minus))) / (2 * h)

    exact = sum(onp.sum(g * vi) for g, vi in zip(vjp(w), v))
    numeric = (4 * central_difference(step / 2) - central_difference(step)) / 3
    assert abs(exact - numeric) <= rtol * max(abs(exact), abs(numeric)), (
        f"autograd <J^T w, v> = {exact!r}, finite differences <w, J v> = {numeric!r}"
    )
