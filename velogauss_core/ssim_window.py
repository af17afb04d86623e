"""The SSIM window shared by `velogauss_ref.metrics` and `velogauss_fast.metrics` (VG-METRIC-SSIM)."""

import numpy as np

from velogauss_core.constants import SSIM_SIGMA, SSIM_WINDOW


def gaussian_window(size: int = SSIM_WINDOW, sigma: float = SSIM_SIGMA) -> np.ndarray:
    """The 1D SSIM window (size,): exp(-x^2 / (2 sigma^2)) at x = -(size-1)/2 .. (size-1)/2, summing to 1.

    The 2D window is its outer product with itself (scipy.ndimage.gaussian_filter's
    kernel with radius 5, which scikit-image's SSIM uses).
    """
    x = np.arange(size) - (size - 1) / 2
    g = np.exp(-0.5 * x**2 / sigma**2)
    return g / g.sum()
