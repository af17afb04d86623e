"""The rasterizer's modes (spec/rendering.md, VG-RENDER), shared by both twins and the config.

"classic" dilates every splat by EPS2D and composites it with its own opacity, as 3DGS
does. "antialiased" is Mip-Splatting's 2D Mip filter: a dilation of MIP_FILTER_VARIANCE,
about a pixel's own box filter, and the opacity times VG-PROJ's `compensation`, the splat's
integral before the dilation over its integral after (gsplat's `rasterize_mode=
"antialiased"`). A splat thinner than a pixel is then dimmed instead of widened, so a
Gaussian scaled by λ renders close to λ times its image, which a stretching body needs
(benchmarks/FIDELITY.md, section 0c).
"""

from typing import Literal, get_args

from velogauss_core.constants import EPS2D, MIP_FILTER_VARIANCE

RasterizeMode = Literal["classic", "antialiased"]
RASTERIZE_MODES: tuple[str, ...] = get_args(RasterizeMode)


def check_mode(mode):
    """Raise ValueError naming `mode` unless it is one of RASTERIZE_MODES."""
    if mode not in RASTERIZE_MODES:
        raise ValueError(f"mode: expected one of {RASTERIZE_MODES}, got {mode!r}")


def dilation(mode: RasterizeMode) -> float:
    """The variance (px^2) VG-PROJ adds to both diagonal entries of every 2D covariance."""
    return MIP_FILTER_VARIANCE if mode == "antialiased" else EPS2D


def splat_opacities(opacities, compensation, mode: RasterizeMode):
    """The opacities (N,) the compositing uses: `opacities` under "classic", times VG-PROJ's
    `compensation` (N,) under "antialiased". NumPy, autograd or torch arrays alike."""
    return opacities * compensation if mode == "antialiased" else opacities
