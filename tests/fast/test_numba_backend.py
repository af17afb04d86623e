"""velogauss_fast.backends.numba_backend: the compiled CPU compositing (VG-BLEND, VG-RENDER).

Agreement with the reference and the hard cases run through the `backend` parametrization
of tests/fast/test_raster.py and test_render_hard_cases.py. Here: the kernels visit
exactly the torch backend's pairs, match its analytic backward on scenes with thousands of
pairs, early stops and clamped alphas, keep the forward's exp recurrence exact on long
rows, and give the same result whatever the thread count.
"""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.render_cases import assert_close, random_scene, scene_to_torch, to_numpy
from tests.fast.test_raster import composite_and_gradients, composite_inputs
from velogauss_fast import composite as compositing
from velogauss_fast import raster
from velogauss_fast.spans import SPAN_COLUMNS, pair_table, row_spans
from velogauss_fast.backends import numba_backend, numba_kernels
from velogauss_fast.backends.numba_backend import CompositeNumba, _parameters
from velogauss_fast.covariance import covariance_3d
from velogauss_fast.projection import project_gaussians
from velogauss_core.constants import ALPHA_MAX


def spans_of(scene, dtype=torch.float64):
    t = scene_to_torch(scene, dtype, "cpu")
    proj = project_gaussians(t["means"], covariance_3d(t["quats"], t["scales"]), t["viewmat"], t["K"],
                             scene["width"], scene["height"])
    spans = row_spans(proj["mean2d"], proj["conic"], t["opacities"], proj["radius"], proj["depth"],
                              proj["valid"], scene["width"], scene["height"])
    return proj, t, spans


@pytest.mark.spec("VG-RENDER")
@given(st.integers(0, 2**32 - 1), st.sampled_from([torch.float32, torch.float64]), st.integers(1, 4))
def test_kernels_visit_the_pair_tables_pairs(seed, dtype, n_parts):
    # Wide and thin splats (an edge-on disc is near-indefinite), partly off-screen.
    rng = np.random.default_rng(seed)
    scene = random_scene(rng, int(rng.integers(1, 60)), int(rng.integers(4, 30)), int(rng.integers(4, 30)),
                         scale_px=(0.05, 8.0), margin=10.0)
    scene["scales"][::3, 2] = 1e-9
    proj, t, spans = spans_of(scene, dtype)
    pairs = pair_table(spans)
    prm = _parameters(t["colors"], spans)
    counts = np.zeros(n_parts, dtype=np.int64)
    numba_kernels.count_pairs(n_parts, prm, scene["width"], counts)
    assert counts.sum() == len(pairs.gid)
    # Pair by pair: the (Gaussian, pixel) set of the kernels' row spans is the table's.
    visited = set()
    for rank in range(len(prm)):
        for row in range(int(prm[rank, numba_kernels.Y0]), int(prm[rank, numba_kernels.Y1]) + 1):
            xa, xb, _ = numba_kernels.row_span(prm, rank, row, scene["width"])
            visited.update((int(spans.ids[rank]), row * scene["width"] + x) for x in range(xa, xb + 1))
    assert visited == set(zip(pairs.gid.tolist(), pairs.pix.tolist()))


@pytest.mark.spec("VG-BLEND", "VG-RENDER")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_numba_matches_the_torch_backends_analytic_backward(seed):
    # As in test_raster.test_analytic_backward_matches_autograd: 100 splats of 1.5-4 px on
    # 20 x 16 px, every fifth fully opaque: early stops, clamped alphas, runs of tens.
    rng = np.random.default_rng(seed)
    scene = random_scene(rng, 100, 20, 16, scale_px=(1.5, 4.0), opacity=(0.5, 1.0))
    scene["opacities"][::5] = 1.0
    scene["background"] = rng.uniform(size=3)
    leaves, pairs = composite_inputs(scene, "cpu")
    _, _, spans = spans_of(scene)
    assert len(pairs.gid) > 2000
    out_t, grads_t = composite_and_gradients(compositing.Composite.apply, leaves, pairs, seed)
    out_n, grads_n = composite_and_gradients(lambda *xs: CompositeNumba.apply(*xs[:5], spans), leaves, spans, seed)
    # Forward: T as a running product (numba) or exp of float64 log sums (torch), alphas
    # from the exp recurrence: observed <= 4e-14 of the largest entry over seeds 0-5.
    # Backward: numba recovers T by division and sums per part: observed <= 1.5e-14.
    for name, a, b in zip(("image", "T"), out_n, out_t):
        assert_close(a, to_numpy(b), 1e-12, name=name)
    for name, a, b in zip(("mean2d", "conic", "opacity", "rgb", "background"), grads_n, grads_t):
        assert_close(a, to_numpy(b), 1e-11, name=f"gradient of {name}", floor=1.0)
    # The cases are exercised: clamped alphas and pixels stopped early.
    alpha = compositing.pair_alpha(compositing.gaussian_columns(*(x.detach() for x in leaves[:4])),
                               compositing.pixel_centres(20, 16, torch.float64, "cpu"), pairs.gid, pairs.pix)
    assert (alpha == ALPHA_MAX).any() and (out_t[1] < 1e-3).any()


@pytest.mark.spec("VG-ALPHA", "VG-RENDER")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_exp_recurrence_is_exact_along_long_rows(dtype):
    # Splats 40-120 px wide on a 400 x 6 image: rows of hundreds of pixels, where the
    # forward advances o exp(-sigma) by products (restarting every EXP_RESTART pixels).
    rng = np.random.default_rng(5)
    scene = random_scene(rng, 6, 400, 6, scale_px=(40.0, 120.0), opacity=(0.3, 0.9))
    scene["background"] = rng.uniform(size=3)
    t = scene_to_torch(scene, dtype, "cpu")
    image_t, alpha_t, meta = raster.rasterize(**scene_to_torch(scene, torch.float64, "cpu"), backend="torch")
    image_n, alpha_n, _ = raster.rasterize(**t, backend="numba")
    assert meta["n_pairs"] > 5000
    # float64: within a few roundings of the direct exps (observed 7e-15; without the
    # restarts the recurrence drifts by ~1e-11 over such rows); float32: float64
    # compositing of float32 inputs (observed 9e-8).
    rtol = 1e-13 if dtype == torch.float64 else 1e-5
    assert_close(image_n, to_numpy(image_t), rtol, name="image")
    assert_close(alpha_n, to_numpy(alpha_t), rtol, name="alpha")


@pytest.mark.spec("VG-RENDER")
def test_thread_count_changes_nothing_but_rounding():
    rng = np.random.default_rng(7)
    scene = random_scene(rng, 200, 33, 17, scale_px=(1.0, 5.0), opacity=(0.2, 1.0))
    scene["background"] = rng.uniform(size=3)
    cot = [torch.from_numpy(rng.standard_normal(s)) for s in ((17, 33, 3), (17, 33, 1))]
    previous = numba_backend.set_num_threads(0)
    results = []
    try:
        for n in (1, 2, 5):
            numba_backend.set_num_threads(n)
            t = scene_to_torch(scene, torch.float64, "cpu", requires_grad=True)
            image, alpha, _ = raster.rasterize(**t, backend="numba")
            grads = torch.autograd.grad((image * cot[0]).sum() + (alpha * cot[1]).sum(),
                                        [t[k] for k in ("means", "quats", "scales", "opacities", "colors")])
            results.append((image, alpha, grads))
    finally:
        numba_backend.set_num_threads(previous)
    (image_1, alpha_1, grads_1), *others = results
    for image, alpha, grads in others:
        # Each pixel is composited by one part, in rank order: bit for bit.
        assert torch.equal(image, image_1) and torch.equal(alpha, alpha_1)
        # Per-Gaussian sums are split across parts, then added in part order.
        for g, g1 in zip(grads, grads_1):
            assert_close(g, to_numpy(g1), 1e-13, floor=1.0)


@pytest.mark.spec("VG-RENDER")
@pytest.mark.skipif(not torch.cuda.is_available(), reason="numba's refusal of CUDA tensors needs a CUDA device")
def test_numba_refuses_cuda_tensors():
    scene = scene_to_torch(random_scene(np.random.default_rng(3), 5, 8, 6), torch.float32, "cuda")
    with pytest.raises(ValueError, match="^backend: 'numba' needs CPU tensors"):
        raster.rasterize(**scene, backend="numba")


def test_kernel_columns_follow_the_span_columns():
    # The kernels index spans.geom by position: a reordering in spans.py must show here.
    named = {"u": "U", "v": "V", "a": "CA", "b": "CB", "c": "CC", "opacity": "OPACITY", "two_as": "TWO_AS",
             "det": "DET", "inv_a": "INV_A", "b_over_a": "B_OVER_A", "definite": "DEFINITE", "x0": "X0",
             "x1": "X1", "y0": "Y0", "y1": "Y1"}
    assert [getattr(numba_kernels, named[c]) for c in SPAN_COLUMNS] == list(range(len(SPAN_COLUMNS)))
    assert (numba_kernels.RED, numba_kernels.GREEN, numba_kernels.BLUE) == tuple(
        range(len(SPAN_COLUMNS), numba_kernels.N_COLUMNS))
