"""View-dependent colour from real spherical harmonics (the 3DGS basis).

spec/rendering.md, VG-SH.
"""

import autograd.numpy as np

from velogauss_core.checks import check_degree
from velogauss_core.constants import VIEW_DIRECTION_MIN
from velogauss_ref.checks import check_array

# Real SH normalisation constants of 3DGS's utils/sh_utils.py, bands 0..3.
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (
    1.0925484305920792,
    -1.0925484305920792,
    0.31539156525252005,
    -1.0925484305920792,
    0.5462742152960396,
)
C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)


def sh_to_color(sh, dirs, degree):
    """RGB seen along each viewing direction: max(0, sum_lm c_lm Y_lm(d) + 0.5) (VG-SH).

    sh: (N, K, 3) coefficients c_lm in 3DGS order with K >= (degree + 1)^2 (later
    coefficients are ignored); dirs: (N, 3) viewing directions of any length (normalised
    here; one shorter than VIEW_DIRECTION_MIN is taken as +z); degree in {0, 1, 2, 3} -> rgb: (N, 3).
    The clamp at 0 passes no gradient below it. Bad degree, too few coefficients,
    non-finite or wrongly shaped input raise ValueError.
    """
    check_degree("degree", degree)
    check_array("sh", sh, (None, None, 3))
    n_coeffs = (degree + 1) ** 2
    if np.shape(sh)[1] < n_coeffs:
        raise ValueError(f"sh: degree {degree} needs {n_coeffs} coefficients, got {np.shape(sh)[1]}")
    check_array("dirs", dirs, (np.shape(sh)[0], 3))

    Y = sh_basis(_unit(dirs), degree)  # (N, n_coeffs)
    rgb = np.sum(Y[:, :, None] * sh[:, :n_coeffs, :], axis=1) + 0.5
    return np.maximum(rgb, 0.0)


def sh_basis(d, degree):
    """The (degree + 1)^2 real SH basis functions Y_lm at unit directions d (N, 3) -> (N, K).

    Band by band as in 3DGS's eval_sh (including its sign convention), so coefficients
    trained by 3DGS-style code mean the same here.
    """
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    Y = [C0 * np.ones(np.shape(x))]
    if degree >= 1:
        Y += [-C1 * y, C1 * z, -C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        Y += [
            C2[0] * x * y,
            C2[1] * y * z,
            C2[2] * (2 * zz - xx - yy),
            C2[3] * x * z,
            C2[4] * (xx - yy),
        ]
    if degree >= 3:
        Y += [
            C3[0] * y * (3 * xx - yy),
            C3[1] * x * y * z,
            C3[2] * y * (4 * zz - xx - yy),
            C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            C3[4] * x * (4 * zz - xx - yy),
            C3[5] * z * (xx - yy),
            C3[6] * x * (xx - 3 * yy),
        ]
    return np.stack(Y, axis=-1)


def camera_centre(viewmat):
    """World position of the camera centre, -W^T t, of a world-to-camera viewmat (4, 4) -> (3,)."""
    check_array("viewmat", viewmat, (4, 4))
    return -np.dot(viewmat[:3, :3].T, viewmat[:3, 3])


def viewing_directions(means, viewmat):
    """Unnormalised viewing directions d_i = mu_i - camera_centre (VG-SH): (N, 3) -> (N, 3)."""
    check_array("means", means, (None, 3))
    return means - camera_centre(viewmat)


def _unit(dirs):
    """dirs / |dirs| (N, 3) -> (N, 3), with a direction shorter than VIEW_DIRECTION_MIN replaced
    by +z before dividing (no 0/0, no NaN gradient, no colour decided by rounding noise)."""
    n2 = np.sum(dirs * dirs, axis=-1, keepdims=True)
    zero = n2 < VIEW_DIRECTION_MIN**2
    return np.where(zero, np.array([0.0, 0.0, 1.0]), dirs) / np.sqrt(np.where(zero, 1.0, n2))
