"""View-dependent colour from real spherical harmonics (3DGS basis), in torch.

Twin of `velogauss_ref.sh` (spec/rendering.md, VG-SH).
"""

import torch

from velogauss_fast.checks import check_array
from velogauss_core.checks import check_degree
from velogauss_core.constants import VIEW_DIRECTION_MIN

# Real SH normalisation constants of 3DGS's sh_utils.py (degree 0..3).
C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
C3 = (
    -0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
    -0.4570457994644658, 1.445305721320277, -0.5900435899266435,
)


def sh_to_color(sh, dirs, degree):
    """RGB of each Gaussian seen along `dirs`: max(0, sum_lm c_lm Y_lm(d) + 0.5) (VG-SH).

    sh: (N, K, 3) coefficients with K >= (degree + 1)^2 (later bands ignored); dirs: (N, 3)
    viewing directions, any length (normalised here; one shorter than VIEW_DIRECTION_MIN is taken as +z);
    degree in {0, 1, 2, 3} -> rgb (N, 3). The clamp at 0 passes no gradient below it.
    """
    check_degree("degree", degree)
    check_array("sh", sh, (None, None, 3))
    if sh.shape[1] < (degree + 1) ** 2:
        raise ValueError(f"sh: degree {degree} needs {(degree + 1) ** 2} coefficients, got {sh.shape[1]}")
    check_array("dirs", dirs, (sh.shape[0], 3))

    n2 = (dirs * dirs).sum(-1, keepdim=True)
    zero = n2 < VIEW_DIRECTION_MIN**2
    plus_z = torch.tensor([0.0, 0.0, 1.0], dtype=dirs.dtype, device=dirs.device)
    d = torch.where(zero, plus_z, dirs) / torch.sqrt(torch.where(zero, torch.ones_like(n2), n2))
    x, y, z = d[:, 0:1], d[:, 1:2], d[:, 2:3]

    out = C0 * sh[:, 0]
    if degree >= 1:
        out = out - C1 * y * sh[:, 1] + C1 * z * sh[:, 2] - C1 * x * sh[:, 3]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        xy, yz, xz = x * y, y * z, x * z
        out = (
            out
            + C2[0] * xy * sh[:, 4]
            + C2[1] * yz * sh[:, 5]
            + C2[2] * (2.0 * zz - xx - yy) * sh[:, 6]
            + C2[3] * xz * sh[:, 7]
            + C2[4] * (xx - yy) * sh[:, 8]
        )
    if degree >= 3:
        out = (
            out
            + C3[0] * y * (3 * xx - yy) * sh[:, 9]
            + C3[1] * xy * z * sh[:, 10]
            + C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
            + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
            + C3[4] * x * (4 * zz - xx - yy) * sh[:, 13]
            + C3[5] * z * (xx - yy) * sh[:, 14]
            + C3[6] * x * (xx - 3 * yy) * sh[:, 15]
        )
    return torch.clamp(out + 0.5, min=0.0)


def viewing_directions(means, viewmat):
    """Unnormalised viewing directions mu_i - camera_centre, camera_centre = -W^T t (VG-SH).

    means: (N, 3) world; viewmat: (4, 4) world-to-camera -> (N, 3).
    """
    check_array("means", means, (None, 3))
    check_array("viewmat", viewmat, (4, 4))
    return means + viewmat[:3, :3].T @ viewmat[:3, 3]
