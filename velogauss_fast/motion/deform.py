"""Residual auxiliary deformation field and its composition with the base state, in torch.

Twin of `velogauss_ref.motion.deform` (spec/motion.md, VG-ADF and VG-ADF-COMPOSE; paper
eqs. 5-6).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_fast.motion.scalars import check_time, time_tensor
from velogauss_fast.nn import mlp, positional_encoding
from velogauss_fast.quaternion import normalize_quat, quat_multiply


def adf_residual(params, x0, t, z, cfg):
    """(dx, dq, ds) = F_MLP(gamma(x0), gamma(t), z): the correction to the base state (VG-ADF).

    params: motion parameter dict (uses params["adf"], 10 outputs); x0: (N, 3) canonical
    means; t: scalar time; z: (N, L) codes; cfg: MotionSpec (cfg.n_freqs_adf_x,
    cfg.n_freqs_adf_t) -> dx (N, 3), dq (N, 4) = (1, 0, 0, 0) + o[3:7], ds (N, 3) (log scale).
    """
    check_array("x0", x0, (None, 3))
    check_array("z", z, (x0.shape[0], None))
    check_time("t", t)
    gt = positional_encoding(time_tensor(t, x0), cfg.n_freqs_adf_t).expand(x0.shape[0], -1)
    o = mlp(params["adf"], torch.cat([positional_encoding(x0, cfg.n_freqs_adf_x), gt, z], dim=-1))
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=o.dtype, device=o.device)
    return o[:, 0:3], identity + o[:, 3:7], o[:, 7:10]


def compose_state(x_star, q_star, s_star, dx, dq, ds):
    """x = x* + dx, q = normalise(q* (x) dq), s = s* exp(ds) (VG-ADF-COMPOSE).

    All (N, .) with q*, dq (N, 4) of any norm; a product below QUAT_ZERO_NORM_SQ gives
    the identity quaternion. Returns x (N, 3), q (N, 4) unit, s (N, 3).
    """
    check_array("x_star", x_star, (None, 3))
    n = x_star.shape[0]
    check_array("q_star", q_star, (n, 4))
    check_array("s_star", s_star, (n, 3))
    check_array("dx", dx, (n, 3))
    check_array("dq", dq, (n, 4))
    check_array("ds", ds, (n, 3))
    return x_star + dx, normalize_quat(quat_multiply(q_star, dq)), s_star * torch.exp(ds)
