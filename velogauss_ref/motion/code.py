"""Physics code z = E(gamma(x0)) of each particle.

spec/motion.md, VG-CODE.
"""

from velogauss_ref.checks import check_array
from velogauss_ref.nn import mlp, positional_encoding


def physics_code(params, x0, cfg):
    """z = E(gamma(x0)): the material code a particle carries for all time (VG-CODE).

    params: motion parameter dict (uses params["code"], the MLP E); x0: (N, 3) canonical
    positions; cfg: MotionSpec (gamma with cfg.n_freqs_x frequencies) -> z: (N, cfg.code_dim).
    Non-finite or wrongly shaped x0 raises ValueError.
    """
    check_array("x0", x0, (None, 3))
    return mlp(params["code"], positional_encoding(x0, cfg.n_freqs_x))
