"""Export the Gaussians of a trained model at one time as a standard 3DGS PLY file.

The layout is the one the original 3D Gaussian Splatting code writes (`GaussianModel.save_ply`)
and that splat viewers (SuperSplat, antimatter15/splat, the SIBR viewer, gsplat's tools)
read: one `vertex` element, `binary_little_endian`, every property `float`, in this order

    x, y, z, nx, ny, nz, f_dc_0, f_dc_1, f_dc_2, f_rest_0 … f_rest_{3((D+1)²−1)−1},
    opacity, scale_0, scale_1, scale_2, rot_0, rot_1, rot_2, rot_3

- normals are zero (3DGS writes zeros too);
- `f_dc_c` is the degree-0 SH coefficient of channel c (VG-SH: `rgb = C0·f_dc + 0.5 + …`);
- `f_rest` is channel-major: all higher-order coefficients of red (SH index 1 … (D+1)²−1),
  then green, then blue — 3DGS stores features `(N, (D+1)²−1, 3)` and writes them
  transposed to `(N, 3, (D+1)²−1)`;
- `opacity` is the logit (viewers apply a sigmoid), `scale_k` the natural log of the
  standard deviation (viewers apply exp), `rot` the normalised quaternion (w, x, y, z).
"""

import numpy as np
import torch

from velogauss.data.ply import vertex_ply_bytes
from velogauss.io_utils import to_numpy, write_bytes
from velogauss_fast.quaternion import normalize_quat
from velogauss_fast.sh import C0
from velogauss_core.checks import check_array
from velogauss_core.constants import EXPORT_OPACITY_CLAMP, TIME_HORIZON


def ply_property_names(sh_degree):
    """The vertex property names of a 3DGS PLY of SH degree `sh_degree`, in file order."""
    if isinstance(sh_degree, bool) or not isinstance(sh_degree, (int, np.integer)) or not 0 <= sh_degree <= 3:
        raise ValueError(f"sh_degree: expected an integer in 0..3, got {sh_degree!r}")
    n_rest = 3 * ((sh_degree + 1) ** 2 - 1)
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(n_rest)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def gaussians_to_table(means, quats, scales, opacities, colors, sh_degree):
    """The `(N, P)` float32 table of a 3DGS PLY (columns as `ply_property_names(sh_degree)`).

    `means (N, 3)` world units; `quats (N, 4)` (w, x, y, z), any norm — normalised here by
    `normalize_quat`, a quaternion with `|q|² < QUAT_ZERO_NORM_SQ` is written as the identity
    (spec/conventions.md);
    `scales (N, 3)` standard deviations > 0; `opacities (N,)` in [0, 1], clamped to
    `[EXPORT_OPACITY_CLAMP, 1 − EXPORT_OPACITY_CLAMP]` before the logit so that fully
    transparent or opaque Gaussians stay finite; `colors (N, (D+1)², 3)` SH coefficients
    with `D ≥ sh_degree` (coefficients beyond `sh_degree` are dropped) or `(N, 3)` RGB in
    [0, 1] (converted to the DC coefficient, `(rgb − 0.5) / C0`, with `sh_degree` 0).
    Raises ValueError naming the argument for a wrong shape, a non-finite value, a scale
    ≤ 0 or an opacity outside [0, 1].
    """
    means = _as_f64("means", means, (None, 3))
    n = means.shape[0]
    quats = _as_f64("quats", quats, (n, 4))
    scales = _as_f64("scales", scales, (n, 3))
    opacities = _as_f64("opacities", opacities, (n,))
    colors = _as_f64("colors", colors, None)
    names = ply_property_names(sh_degree)
    if colors.shape == (n, 3):
        if sh_degree != 0:
            raise ValueError(f"colors: RGB colours (N, 3) export with sh_degree 0, got sh_degree={sh_degree}")
        colors = ((colors - 0.5) / C0)[:, None, :]
    n_coeffs = (sh_degree + 1) ** 2
    if colors.ndim != 3 or colors.shape[0] != n or colors.shape[2] != 3 or colors.shape[1] < n_coeffs:
        raise ValueError(f"colors: expected ({n}, >= {n_coeffs}, 3) SH coefficients or ({n}, 3) RGB, got {colors.shape}")
    if np.any(scales <= 0):
        raise ValueError(f"scales: expected standard deviations > 0, found min {scales.min():.3g}")
    if np.any((opacities < 0) | (opacities > 1)):
        raise ValueError(f"opacities: expected values in [0, 1], found [{opacities.min():.3g}, {opacities.max():.3g}]")

    unit = normalize_quat(torch.from_numpy(quats)).numpy()
    clamped = np.clip(opacities, EXPORT_OPACITY_CLAMP, 1.0 - EXPORT_OPACITY_CLAMP)
    logit = np.log(clamped) - np.log1p(-clamped)
    rest = colors[:, 1:n_coeffs, :].transpose(0, 2, 1).reshape(n, -1)  # channel-major, as 3DGS
    table = np.concatenate(
        [means, np.zeros((n, 3)), colors[:, 0, :], rest, logit[:, None], np.log(scales), unit], axis=1
    )
    assert table.shape == (n, len(names)), table.shape
    return table.astype(np.float32)


def ply_bytes(table, sh_degree):
    """The bytes of a binary_little_endian 3DGS PLY holding `table` (as `gaussians_to_table`)."""
    names = ply_property_names(sh_degree)
    table = np.ascontiguousarray(table, dtype="<f4")
    if table.ndim != 2 or table.shape[1] != len(names):
        raise ValueError(f"table: expected (N, {len(names)}) for sh_degree {sh_degree}, got {table.shape}")
    return vertex_ply_bytes(table.view(np.dtype([(name, "<f4") for name in names])).reshape(-1))


def export_ply(model, t, path):
    """Write `model.render_inputs_at(t)` to `path` as a 3DGS PLY (atomically); return the Gaussian count.

    `t`: a finite time (normalised, |t| <= TIME_HORIZON: t > max_time is the extrapolated
    future), evaluated without gradients. Raises ValueError naming `t` for a non-finite,
    non-numeric or too distant time.
    """
    t = check_time(t)
    with torch.no_grad():  # inference: no graph of the integration steps is kept
        g = model.render_inputs_at(t)
    table = gaussians_to_table(
        to_numpy(g["means"]), to_numpy(g["quats"]), to_numpy(g["scales"]), to_numpy(g["opacities"]).reshape(-1),
        to_numpy(g["colors"]), int(g["sh_degree"]),
    )
    write_bytes(path, ply_bytes(table, int(g["sh_degree"])))
    return table.shape[0]


def check_time(t, name="t"):
    """Return `t` as a float; ValueError naming `name` when it is not a finite real number or
    lies beyond the horizon |t| <= TIME_HORIZON (velogauss_core.constants, where the why is)."""
    try:
        value = float(t)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a finite real number, got {t!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{name}: expected a finite real number, got {t!r}")
    if abs(value) > TIME_HORIZON:
        raise ValueError(f"{name}: {t} is beyond the horizon |t| <= {TIME_HORIZON:g} (TIME_HORIZON: the model has "
                         "seen t in [0, max_time], and integration time grows with |t|)")
    return value


def _as_f64(name, x, shape):
    return np.asarray(check_array(name, np.asarray(x, dtype=np.float64), shape), dtype=np.float64)
