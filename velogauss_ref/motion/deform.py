"""Residual auxiliary deformation field and its composition with the base state (paper eqs. 5-6).

spec/motion.md, VG-ADF and VG-ADF-COMPOSE.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array, check_scalar
from velogauss_ref.nn import mlp, positional_encoding
from velogauss_ref.quaternion import IDENTITY_QUAT, normalize_quat, quat_multiply


def adf_residual(params, x0, t, z, cfg):
    """(dx, dq, ds): the correction of the base state at time t (VG-ADF).

    o = mlp(params["adf"], [gamma(x0), gamma(t), z]) with 10 outputs, gamma with
    cfg.n_freqs_adf_x / cfg.n_freqs_adf_t frequencies (gamma(t) repeated for every particle).
    x0: (N, 3) canonical means; t: scalar time, any real value; z: (N, L) codes ->
    dx = o[:, 0:3] (N, 3), dq = (1, 0, 0, 0) + o[:, 3:7] (N, 4), ds = o[:, 7:10] (N, 3), a log
    scale. A zero last layer gives the identity correction (0, (1, 0, 0, 0), 0).
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x0", x0, (None, 3))
    n = np.shape(x0)[0]
    check_array("z", z, (n, None))
    check_scalar("t", t)
    t_column = t * np.ones((n, 1))
    features = np.concatenate(
        [positional_encoding(x0, cfg.n_freqs_adf_x), positional_encoding(t_column, cfg.n_freqs_adf_t), z], axis=1
    )
    o = mlp(params["adf"], features)
    # dq is predicted as an offset from the identity rotation, so a zero output changes nothing.
    return o[:, 0:3], IDENTITY_QUAT + o[:, 3:7], o[:, 7:10]


def compose_state(x_star, q_star, s_star, dx, dq, ds):
    """x = x* + dx, q = normalise(q* (x) dq), s = s* exp(ds) (VG-ADF-COMPOSE; paper eq. 6).

    x_star, dx: (N, 3); q_star, dq: (N, 4), any norm; s_star: (N, 3); ds: (N, 3) log-scale
    correction -> x (N, 3), q (N, 4) unit, s (N, 3). R(q) = R(q*) R(dq): the correction acts
    in the base state's frame. A product below QUAT_ZERO_NORM_SQ gives the identity
    quaternion. Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x_star", x_star, (None, 3))
    n = np.shape(x_star)[0]
    check_array("q_star", q_star, (n, 4))
    check_array("s_star", s_star, (n, 3))
    check_array("dx", dx, (n, 3))
    check_array("dq", dq, (n, 4))
    check_array("ds", ds, (n, 3))
    return x_star + dx, normalize_quat(quat_multiply(q_star, dq)), s_star * np.exp(ds)
