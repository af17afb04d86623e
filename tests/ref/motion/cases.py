"""Shared NumPy-only machinery of the motion and physics tests (reference and fast alike).

Small configurations, parameter dicts drawn by `init_motion_params` (made fully non-zero,
or with constant coefficients for closed-form motions), the column masks of a few scene
profiles, `flat_params` and `flat_outputs`, which let `check_grads_fd` differentiate a
parameter dict and a function with several outputs, and `affine_matrix`, A(w) by hand.
"""

import autograd.numpy as anp
import numpy as np
from autograd.misc import flatten

from velogauss_core.motion import COLUMN_GROUPS, N_BASIS, init_motion_params, mlp_layers, MotionSpec, network_shapes

# Finite-difference step of the gradient checks that run through the networks
# (check_grads_fd's default is 1e-6). At 1e-6 rounding of the differences (eps times the
# size of the intermediates, over the step, tripled by Richardson) reaches ~1e-9, which
# fails the 1e-6 relative check where a random projection <w, J v> happens to be ~1e-4
# (seen: the masked coefficients at n_freqs_t = 2). At 1e-4 rounding drops 100-fold and
# Richardson's truncation error (~step^4 |f^(5)|) stays ~1e-16 for these smooth O(1)
# functions; every threshold the probes could cross (step counts of VG-INTEG, the zero
# quaternion) is kept more than 1e-2 away.
FD_STEP = 1e-4

# Small networks keep the reference's per-point autograd residuals fast while every branch
# of the model runs (gamma of t with a frequency, code, mixing, ADF inputs).
SMALL = dict(n_freqs_x=2, n_freqs_t=1, n_freqs_adf_x=2, n_freqs_adf_t=1, code_dim=3, n_patterns=4,
             hidden=8, depth=2)


def column_mask(*groups):
    """Bool (12,) selecting the VG-BASIS columns of the named COLUMN_GROUPS."""
    mask = np.zeros(N_BASIS, dtype=bool)
    for group in groups:
        mask[list(COLUMN_GROUPS[group])] = True
    return mask


# Column mask of a rigid scene: translation and rotation only.
RIGID_MASK = column_mask("translation", "rotation")
# Translation columns only: the acceleration mask of a scene that only translates (VG-ACC).
TRANSLATION_MASK = column_mask("translation")


def small_cfg(mask=None, **overrides):
    return MotionSpec(**{**SMALL, **overrides}, mask=mask)


def random_params(seed, cfg, scale=1.0):
    """init_motion_params plus noise on every array, so that no layer is exactly zero.

    Training zero-initialises some layers (the ADF's last layer); a test of every path
    needs them non-zero. `scale` multiplies the noise (0.3 standard deviations).
    """
    rng = np.random.default_rng(seed)
    params = init_motion_params(rng, cfg)
    return map_leaves(lambda a: np.asarray(a, dtype=np.float64) + scale * 0.3 * rng.standard_normal(np.shape(a)),
                      params)


def mlp_velocity_params(seed, cfg):
    """`random_params` plus the no-pds velocity MLP "velocity_mlp" (VG-VEL-MLP), noised likewise."""
    rng = np.random.default_rng(seed + 1)
    d_in, d_out = network_shapes(cfg)["velocity_mlp"]
    layers = mlp_layers(rng, d_in, cfg.hidden, cfg.depth, d_out)
    noisy = map_leaves(lambda a: a + 0.3 * rng.standard_normal(np.shape(a)), layers)
    return {**random_params(seed, cfg), "velocity_mlp": noisy}


def map_leaves(fn, node):
    if isinstance(node, dict):
        return {k: map_leaves(fn, v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return type(node)(map_leaves(fn, v) for v in node)
    return fn(node)


def constant_coefficient_params(seed, cfg, w, acc=None):
    """Parameters whose coefficients are w (12,) for every particle and time.

    The time network's last layer is zeroed with bias tile(w, K), so all K patterns equal w
    and any softmax mixture returns w. acc (ACC_POLY_DEGREE + 1, 12), if given, sets every
    pattern's acceleration polynomial likewise. The code network stays random, so the
    Eulerian field still routes through E(gamma(x)) -- with no effect on the value. The
    patterns are written about the world's origin (VG-COEF-CENTRE's centres zero), so w is the
    world-frame field's.
    """
    params = random_params(seed, cfg)
    params["centre"] = np.zeros_like(params["centre"])
    K = cfg.n_patterns
    W, _ = params["time"][-1]
    params["time"][-1] = (np.zeros_like(W), np.tile(np.asarray(w, dtype=np.float64), K))
    if acc is not None:
        params["acc"] = np.repeat(np.asarray(acc, dtype=np.float64)[:, None, :], K, axis=1)
    return params


def flat_params(params):
    """(theta, unflatten): the dict's arrays as one float64 vector, and its autograd-traceable inverse.

    check_grads_fd differentiates arrays only; f(unflatten(theta), ...) makes a parameter
    dict one of them.
    """
    theta, unflatten = flatten(params)
    return np.asarray(theta, dtype=np.float64), unflatten


def flat_outputs(fn):
    """fn with its tuple of outputs raveled into one array, for check_grads_fd (autograd-traceable)."""
    return lambda *args: anp.concatenate([anp.ravel(out) for out in fn(*args)])


def affine_matrix(w):
    """A(w) of VG-BASIS written out by hand from the spec, for (12,) w: an independent oracle."""
    return np.array([[w[6], w[9] - w[5], w[4] + w[11]],
                      [w[9] + w[5], w[7], w[10] - w[3]],
                      [w[11] - w[4], w[10] + w[3], w[8]]])
