"""The motion parameter dict drawn with NumPy (spec/motion.md, "Parameters and configuration").

`MotionConfig` and the layout's sizes live in `velogauss_core.motion`; this is the
reference's initialisation, which `velogauss_fast.motion.params.init_motion_params` mirrors
in torch.
"""

import numpy as onp

from velogauss_core.constants import ACC_POLY_DEGREE
from velogauss_core.motion import N_BASIS, network_shapes


def init_motion_params(rng, cfg):
    """A fresh parameter dict for `cfg` (`velogauss_core.motion.MotionConfig`), drawn from the
    NumPy Generator `rng`.

    Layout (all float64 arrays; MLPs are lists of (W (d_in, d_out), b (d_out,)), sizes from
    `velogauss_core.motion.network_shapes`):
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
    L, K = cfg.code_dim, cfg.n_patterns
    H, D = cfg.hidden, cfg.depth
    (code_in, code_out), (time_in, time_out), (adf_in, adf_out) = (network_shapes(cfg)[k] for k in ("code", "time", "adf"))
    return {
        "code": mlp_layers(rng, code_in, H, D, code_out),
        "mix": [(rng.standard_normal((L, K)) / onp.sqrt(L), onp.zeros(K))],
        "time": mlp_layers(rng, time_in, H, D, time_out, zero_last=True),
        "acc": onp.zeros((ACC_POLY_DEGREE + 1, K, N_BASIS)),
        "adf": mlp_layers(rng, adf_in, H, D, adf_out, zero_last=True),
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
