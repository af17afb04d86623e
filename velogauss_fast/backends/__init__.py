"""Compositing backends of `velogauss_fast.raster.rasterize` beyond the vectorised torch one:
"numba" (compiled CPU kernels) and "gsplat" (optional CUDA kernels)."""

import importlib.util

import torch


def gsplat_available(device):
    """True when `device` is a CUDA device, CUDA works and the gsplat package is importable."""
    return (
        torch.device(device).type == "cuda"
        and torch.cuda.is_available()
        and importlib.util.find_spec("gsplat") is not None
    )


def numba_available():
    """True when the numba package (the CPU kernels' compiler) is importable."""
    return importlib.util.find_spec("numba") is not None
