"""Physics code z = E(gamma(x0)) of each particle, in torch.

Twin of `velogauss_ref.motion.code` (spec/motion.md, VG-CODE).
"""

from velogauss_fast.checks import check_array
from velogauss_fast.nn import mlp, positional_encoding


def physics_code(params, x0, cfg):
    """z = E(gamma(x0)): the material code of each particle (VG-CODE).

    params: motion parameter dict (uses params["code"]); x0: (N, 3) canonical positions;
    cfg: MotionSpec (gamma with cfg.n_freqs_x frequencies) -> z: (N, cfg.code_dim).
    """
    check_array("x0", x0, (None, 3))
    return mlp(params["code"], positional_encoding(x0, cfg.n_freqs_x))
