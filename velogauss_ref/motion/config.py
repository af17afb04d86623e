"""Hyper-parameters and parameter layout of the motion model (spec/motion.md, "Parameters
and configuration").

One frozen `MotionConfig` is shared by `velogauss_ref` and `velogauss_fast`; the parameters
are one dict of plain arrays (`init_motion_params`), which `velogauss_fast.motion.params`
turns into tensors of the same structure.
"""

from dataclasses import dataclass

import numpy as onp

from velogauss_ref.constants import ACC_POLY_DEGREE

N_BASIS = 12
# (dx 3, dq 4, ds 3) of VG-ADF.
ADF_OUTPUTS = 10


@dataclass(frozen=True)
class MotionConfig:
    """Sizes of the motion networks and the basis-column masks (spec/motion.md).

    n_freqs_x: frequencies of gamma(x0) for the code encoder E (VG-CODE);
    n_freqs_t: frequencies of gamma(t) for the time network (VG-COEF; 0 = raw t, which
      extrapolates without periodicity);
    n_freqs_adf_x, n_freqs_adf_t: frequencies of the ADF inputs (VG-ADF);
    code_dim: L, the physics code size; n_patterns: K motion patterns;
    hidden, depth: width and number of hidden layers of every MLP;
    mask: None or 12 bools, the velocity's basis columns (VG-BASIS order);
    acc_mask: None or 12 bools, the acceleration's columns (VG-ACC).
    Masks are stored as tuples of bools so the config stays hashable and serialisable.
    """

    n_freqs_x: int = 4
    n_freqs_t: int = 0
    n_freqs_adf_x: int = 6
    n_freqs_adf_t: int = 6
    code_dim: int = 16
    n_patterns: int = 32
    hidden: int = 64
    depth: int = 3
    mask: tuple | None = None
    acc_mask: tuple | None = None

    def __post_init__(self):
        for name in ("n_freqs_x", "n_freqs_t", "n_freqs_adf_x", "n_freqs_adf_t"):
            _check_int(name, getattr(self, name), 0)
        for name in ("code_dim", "n_patterns", "hidden", "depth"):
            _check_int(name, getattr(self, name), 1)
        for name in ("mask", "acc_mask"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _check_mask(name, value))


def init_motion_params(rng, cfg):
    """A fresh parameter dict for `cfg`, drawn from the NumPy Generator `rng`.

    Layout (all float64 arrays; MLPs are lists of (W (d_in, d_out), b (d_out,))):
      "code": E, 3 (1 + 2 n_freqs_x) -> hidden^depth -> code_dim;
      "mix":  [(A (code_dim, K), c (K,))], the pattern-mixing softmax of VG-COEF;
      "time": 1 (1 + 2 n_freqs_t) -> hidden^depth -> K * 12, the motion patterns P(t);
      "acc":  Q (ACC_POLY_DEGREE + 1, K, 12), the acceleration polynomial of VG-ACC;
      "adf":  3 (1 + 2 n_freqs_adf_x) + (1 + 2 n_freqs_adf_t) + code_dim -> hidden^depth -> 10.
    Hidden layers use PyTorch's default Linear initialisation (uniform within
    +-1/sqrt(fan_in)). Three heads start at zero, so a fresh model is the still canonical
    scene: the time network's last layer (no velocity), Q (no acceleration) and the ADF's
    last layer (identity correction). Their gradients are not zero, so all of them learn.
    """
    L, K, H = cfg.code_dim, cfg.n_patterns, cfg.hidden
    return {
        "code": mlp_layers(rng, 3 * (1 + 2 * cfg.n_freqs_x), H, cfg.depth, L),
        "mix": [(rng.standard_normal((L, K)) / onp.sqrt(L), onp.zeros(K))],
        "time": mlp_layers(rng, 1 + 2 * cfg.n_freqs_t, H, cfg.depth, K * N_BASIS, zero_last=True),
        "acc": onp.zeros((ACC_POLY_DEGREE + 1, K, N_BASIS)),
        "adf": mlp_layers(rng, 3 * (1 + 2 * cfg.n_freqs_adf_x) + 1 + 2 * cfg.n_freqs_adf_t + L, H, cfg.depth,
                           ADF_OUTPUTS, zero_last=True),
    }


def mlp_layers(rng, d_in, hidden, depth, d_out, zero_last=False):
    """Layers (W (d_in, d_out), b) of an MLP d_in -> hidden^depth -> d_out, PyTorch-Linear init;
    the last layer is zero when `zero_last`."""
    dims = [d_in] + [hidden] * depth + [d_out]
    layers = []
    for k, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        bound = 1.0 / onp.sqrt(a)
        if zero_last and k == len(dims) - 2:
            layers.append((onp.zeros((a, b)), onp.zeros(b)))
        else:
            layers.append((rng.uniform(-bound, bound, (a, b)), rng.uniform(-bound, bound, b)))
    return layers


def _check_int(name, value, low):
    if isinstance(value, bool) or not isinstance(value, (int, onp.integer)) or value < low:
        raise ValueError(f"{name}: expected an integer >= {low}, got {value!r}")


def _check_mask(name, value):
    mask = onp.asarray(value)
    if mask.shape != (N_BASIS,) or mask.dtype != bool:
        raise ValueError(f"{name}: expected {N_BASIS} booleans (VG-BASIS columns), got {value!r}")
    return tuple(bool(m) for m in mask)
