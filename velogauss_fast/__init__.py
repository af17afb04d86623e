"""velogauss_fast: the PyTorch twin of velogauss_ref (same module and function names).

Runs on CPU and CUDA in float32 and float64; all training runs on it. The public entry
point is `velogauss_fast.rasterize` (VG-RENDER, gsplat's call shape).
"""

from velogauss_fast.raster import rasterize

__all__ = ["rasterize"]
