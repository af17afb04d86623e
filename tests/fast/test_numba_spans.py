"""velogauss_fast.backends.numba_spans: the numba backend's row spans (VG-RENDER).

The compiled form must give the torch form's Spans: the same Gaussians in the same depth
order, the same boxes bit for bit (pixel membership), every span parameter bit for bit but
the pruning bound 2 a s, whose logarithm may round differently in its last bit, and so the
same (Gaussian, pixel) pairs. Renders through it are tested with the numba backend in
tests/fast/test_raster.py and test_render_hard_cases.py.
"""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.test_numba_backend import spans_of
from tests.fast.render_cases import random_scene
from velogauss_fast.backends.numba_spans import row_spans_numba
from velogauss_fast.raster import rasterize
from velogauss_fast.spans import SPAN_COLUMNS, pair_table, row_spans

TWO_AS = SPAN_COLUMNS.index("two_as")
# 2 a s = 2 a (log(o / ALPHA_MIN) + margin): one logarithm and three roundings, a few ulps.
TWO_AS_RTOL = 8 * np.finfo(np.float64).eps


def assert_same_spans(fast, ref):
    assert torch.equal(fast.ids, ref.ids)
    assert (fast.width, fast.height, fast.n_box) == (ref.width, ref.height, ref.n_box)
    assert fast.geom.dtype == torch.float64 and fast.geom.shape == ref.geom.shape
    others = [k for k in range(len(SPAN_COLUMNS)) if k != TWO_AS]
    assert torch.equal(fast.geom[:, others], ref.geom[:, others])
    torch.testing.assert_close(fast.geom[:, TWO_AS], ref.geom[:, TWO_AS], rtol=TWO_AS_RTOL, atol=0.0)


def spans_both(proj, opacities, width, height):
    args = (proj["mean2d"], proj["conic"], opacities, proj["radius"], proj["depth"], proj["valid"], width, height)
    return row_spans_numba(*args), row_spans(*args)


@pytest.mark.spec("VG-RENDER")
@given(st.integers(0, 2**32 - 1), st.sampled_from([torch.float32, torch.float64]))
def test_numba_spans_are_the_torch_spans(seed, dtype):
    # Wide and thin splats (an edge-on disc is near-indefinite), partly off-screen.
    rng = np.random.default_rng(seed)
    scene = random_scene(rng, int(rng.integers(0, 80)), int(rng.integers(4, 40)), int(rng.integers(4, 40)),
                         scale_px=(0.05, 12.0), margin=15.0)
    scene["scales"][::3, 2] = 1e-9
    proj, t, ref = spans_of(scene, dtype)
    fast, _ = spans_both(proj, t["opacities"], scene["width"], scene["height"])
    assert_same_spans(fast, ref)
    a, b = pair_table(fast), pair_table(ref)
    assert torch.equal(a.gid, b.gid) and torch.equal(a.pix, b.pix)


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_boxes_on_pixel_centres_depth_ties_and_degenerate_conics(dtype):
    # Box edges u +- r exactly on pixel centres j + 0.5 and just beside them, centres off
    # the image and beyond the clamp, equal depths (stable order), an indefinite and a
    # negative conic, zero radius, and invalid Gaussians, which get no span.
    eps = torch.finfo(dtype).eps
    u = torch.tensor([2.5, 2.5 + 4 * eps, 2.5 - 4 * eps, -3.5, 40.0, 1e6, 7.0, 0.5, 3.0], dtype=dtype)
    v = torch.tensor([1.5, 6.5, 0.5, 2.0, -1.0, 3.0, -1e6, 0.5, 3.0], dtype=dtype)
    mean2d = torch.stack([u, v], dim=1)
    conic = torch.tensor([[1.0, 0.0, 1.0], [0.5, 0.2, 0.3], [1.0, 2.0, 1.0], [-1.0, 0.0, 1.0], [2.0, 0.1, 0.4],
                          [1.0, 0.0, 1.0], [0.1, 0.0, 0.1], [0.0, 0.0, 0.0], [1.0, 0.0, 1.0]], dtype=dtype)
    opacity = torch.tensor([0.9, 0.5, 0.02, 0.7, 0.99, 0.4, 0.3, 0.8, 0.6], dtype=dtype)
    radius = torch.tensor([2, 3, 1, 5, 30, 2, 9, 0, 4])
    depth = torch.tensor([1.0, 1.0, 2.0, 0.5, 1.0, 3.0, 0.5, 2.0, 1.0], dtype=dtype)
    valid = torch.tensor([True, True, True, True, True, True, True, True, False])
    fast, ref = spans_both({"mean2d": mean2d, "conic": conic, "radius": radius, "depth": depth, "valid": valid},
                           opacity, 12, 9)
    assert len(ref.ids) == 8
    assert_same_spans(fast, ref)


@pytest.mark.spec("VG-RENDER")
def test_no_valid_gaussian_gives_empty_spans():
    n = 5
    proj = {"mean2d": torch.zeros(n, 2), "conic": torch.ones(n, 3), "radius": torch.ones(n, dtype=torch.int64),
            "depth": torch.ones(n), "valid": torch.zeros(n, dtype=torch.bool)}
    fast, ref = spans_both(proj, torch.full((n,), 0.5), 8, 8)
    assert fast.geom.shape == (0, len(SPAN_COLUMNS)) and fast.n_box == 0
    assert_same_spans(fast, ref)


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("dtype, atol", [(torch.float16, 2e-2), (torch.bfloat16, 1e-1)])
def test_half_precision_renders_through_the_torch_spans(dtype, atol):
    # numba compiles no half-precision arithmetic: such a render takes the torch form of the
    # spans, and the numba backend's image is its float32 image to the dtype's precision.
    rng = np.random.default_rng(3)
    scene = random_scene(rng, 30, 20, 16, scale_px=(0.5, 4.0))
    args = [scene[k] for k in ("means", "quats", "scales", "opacities", "colors", "viewmat", "K")]
    images = {}
    for d in (dtype, torch.float32):
        t = [torch.as_tensor(a, dtype=d) for a in args]
        images[d] = rasterize(*t, scene["width"], scene["height"], backend="numba")[0]
    assert images[dtype].dtype == dtype
    torch.testing.assert_close(images[dtype].float(), images[torch.float32], rtol=0.0, atol=atol)
