"""velogauss_fast.backends: backend selection, and gsplat's CUDA compositing against the torch backend.

The comparison needs a CUDA device and the gsplat package; without them it skips, saying
so. gsplat differs from VG-RENDER by design (velogauss_fast/backends/gsplat_backend.py):
it evaluates every splat of a 16 x 16 tile, clamps alpha at 0.999 and stops at T <= 1e-4.
The scenes below keep opacities under 0.35 and few splats per pixel, where none of the
three can show.
"""

import numpy as np
import pytest
import torch

from tests.fast.render_cases import (RENDER_GRAD_KEYS, assert_close, boundary_band, random_scene, scene_to_torch,
                                     to_numpy)
from velogauss_fast.backends import gsplat_available
from velogauss_fast.raster import rasterize

needs_gsplat = pytest.mark.skipif(
    not gsplat_available("cuda"),
    reason="the gsplat backend needs a CUDA device and the gsplat package (pip install -e .[gsplat])",
)
# Not calibrated on hardware (no GPU where these tests were written): both backends
# composite in float32, gsplat with fused exp and a different summation order; 1e-4 of
# the largest value is ~1000 float32 roundings, the gradients' 1e-3 ten times more for
# the per-splat sums over a tile's pixels.
RTOL_IMAGE, RTOL_GRAD = 1e-4, 1e-3


def gsplat_scene(seed, n=12, width=40, height=24):
    """A float32-friendly scene on two tile rows: opacities < 0.35, 0.5-3 px splats."""
    rng = np.random.default_rng(seed)
    scene = random_scene(rng, n, width, height, scale_px=(0.5, 3.0), opacity=(0.05, 0.34))
    scene["background"] = rng.uniform(size=3)
    return scene


@pytest.mark.spec("VG-RENDER")
def test_gsplat_is_unavailable_for_cpu_tensors():
    assert not gsplat_available("cpu")


@pytest.mark.spec("VG-RENDER")
def test_auto_backend_on_cpu_is_the_numba_backend():
    # Never gsplat on the CPU; numba's float64 running product and the torch backend's
    # log sums differ in the last bits, so equality pins which one ran.
    scene = scene_to_torch(gsplat_scene(0), torch.float64, "cpu")
    auto, numba, vectorised = (rasterize(**scene), rasterize(**scene, backend="numba"),
                               rasterize(**scene, backend="torch"))
    assert torch.equal(auto[0], numba[0]) and torch.equal(auto[1], numba[1])
    assert not torch.equal(auto[0], vectorised[0])
    assert auto[2]["n_pairs"] == numba[2]["n_pairs"] > 0


@pytest.mark.spec("VG-RENDER")
def test_gsplat_backend_on_cpu_tensors_raises():
    with pytest.raises(ValueError, match="^backend:"):
        rasterize(**scene_to_torch(gsplat_scene(0), torch.float32, "cpu"), backend="gsplat")


@pytest.mark.spec("VG-RENDER")
@needs_gsplat
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fast_vs_gsplat(seed):
    scene = gsplat_scene(seed)
    keep = ~boundary_band(scene, 1e-3)
    rng = np.random.default_rng(seed)
    cot_image = torch.tensor(rng.standard_normal((24, 40, 3)) * keep[..., None], dtype=torch.float32, device="cuda")
    cot_alpha = torch.tensor(rng.standard_normal((24, 40, 1)) * keep[..., None], dtype=torch.float32, device="cuda")
    results = {}
    for backend in ("torch", "gsplat"):
        leaves = scene_to_torch(scene, torch.float32, "cuda")
        for k in RENDER_GRAD_KEYS:
            leaves[k].requires_grad_()
        image, alpha, meta = rasterize(**leaves, backend=backend)
        grads = torch.autograd.grad((image * cot_image).sum() + (alpha * cot_alpha).sum(),
                                    [leaves[k] for k in RENDER_GRAD_KEYS])
        results[backend] = (image, alpha, meta, grads)
    image, alpha, meta, grads = results["gsplat"]
    image_t, alpha_t, meta_t, grads_t = results["torch"]
    assert meta["n_pairs"] is None and meta_t["n_pairs"] > 0  # gsplat really ran
    assert_close(image, to_numpy(image_t), RTOL_IMAGE, name="image", mask=keep)
    assert_close(alpha, to_numpy(alpha_t), RTOL_IMAGE, name="alpha", mask=keep)
    for key, g, g_t in zip(RENDER_GRAD_KEYS, grads, grads_t):
        assert_close(g, to_numpy(g_t), RTOL_GRAD, name=f"gradient of {key}", floor=1.0)


@pytest.mark.spec("VG-RENDER")
@needs_gsplat
def test_auto_backend_on_cuda_is_gsplat():
    _, _, meta = rasterize(**scene_to_torch(gsplat_scene(3), torch.float32, "cuda"))
    assert meta["n_pairs"] is None
