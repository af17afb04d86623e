"""Particle velocity Phi(x) w, the Eulerian velocity field v(x, t) and the no-pds MLP velocity.

spec/motion.md, VG-VEL, VG-FIELD and VG-VEL-MLP.
"""

import autograd.numpy as np

from velogauss_ref.checks import check_array, check_scalar
from velogauss_ref.motion.basis import basis_matrix
from velogauss_ref.motion.code import physics_code
from velogauss_ref.motion.coefficients import coefficients
from velogauss_ref.nn import mlp, positional_encoding


def velocity(x, w):
    """v = Phi(x) w (VG-VEL), which equals A(w) x + b(w).

    x: (N, 3) positions; w: (N, 12) coefficients -> v: (N, 3), world units per unit of
    normalised time. Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_array("w", w, (np.shape(x)[0], 12))
    return np.einsum("nik,nk->ni", basis_matrix(x), w)


def velocity_field(params, x, t, cfg):
    """v(x, t) = Phi(x) w(t, E(gamma(x))), the code taken at the query point (VG-FIELD).

    params: motion parameter dict; x: (N, 3) query points; t: scalar time, any real value;
    cfg: MotionSpec -> v: (N, 3). This is the field the physics residuals constrain; it
    agrees with a particle's velocity (code frozen at E(gamma(x0)), VG-TRAJ) at t = 0.
    Non-finite or wrongly shaped input raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    return velocity(x, coefficients(params, t, physics_code(params, x, cfg), cfg))


def mlp_velocity(params, x, t, cfg):
    """v(x, t) = MLP_v([gamma(x), t]): the unconstrained velocity of the "no-pds" ablation (VG-VEL-MLP).

    params: dict with "velocity_mlp" (layers 3 (1 + 2 cfg.n_freqs_x) + 1 -> hidden^depth -> 3);
    x: (N, 3) points; t: scalar time, any real value; cfg: MotionSpec -> v: (N, 3).
    No code and no basis: it moves positions only. Non-finite or wrongly shaped input
    raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_scalar("t", t)
    t_col = t * np.ones((np.shape(x)[0], 1))
    return mlp(params["velocity_mlp"], np.concatenate([positional_encoding(x, cfg.n_freqs_x), t_col], axis=1))
