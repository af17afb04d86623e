"""Optional compositing backends of `velogauss_fast.raster.rasterize` (backend="gsplat")."""

import importlib.util

import torch


def gsplat_available(device):
    """True when `device` is a CUDA device, CUDA works and the gsplat package is importable."""
    return (
        torch.device(device).type == "cuda"
        and torch.cuda.is_available()
        and importlib.util.find_spec("gsplat") is not None
    )
