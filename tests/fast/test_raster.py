"""velogauss_fast.raster: VG-ALPHA, VG-BLEND and VG-RENDER against velogauss_ref.raster.

Beyond agreement with the reference: the analytic backward `_Composite` against the same
formulation left to autograd, the transmittance's float64 prefix sums against exact
products on long runs, and independence of the chunking.
"""

import math
from fractions import Fraction

import numpy as np
import pytest
import torch
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import velogauss_fast
from tests.fast.render_cases import (
    DEVICE_SETTINGS,
    RENDER_GRAD_KEYS,
    RTOL32,
    RTOL64,
    assert_close,
    boundary_band,
    check_agreement,
    check_float32,
    gradcheck_fn,
    random_scene,
    render_gradients,
    scene_to_torch,
    to_numpy,
    to_torch,
)
from tests.ref.cameras import in_view, intrinsics
from tests.ref.test_raster import alpha_margin, alphas_in_range, splats, transmittance_margin, unit_colors
from velogauss_fast import composite as compositing
from velogauss_fast.spans import SPAN_COLUMNS, pair_table, row_spans
from velogauss_fast.covariance import covariance_3d
from velogauss_fast.projection import project_gaussians
from velogauss_fast.raster import blend, rasterize, splat_alpha
from velogauss_ref import raster as ref
from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, TRANSMITTANCE_MIN
from velogauss_core.rendering import RASTERIZE_MODES

DTYPES = [torch.float32, torch.float64]
# Band half-widths (relative): float64 renders reproduce the reference to ~1e-15, so 1e-9
# is already wide; float32 moves means, radii and alphas by ~1e-6 relative, inside 1e-3.
# Gradients are compared outside the wider 1e-6 band of float64.
BAND64, BAND32, GRAD_BAND = 1e-9, 1e-3, 1e-6
# The absolute error of log T claimed by velogauss_fast.raster's docstring.
LOG_T_ERROR = 1e-9


# ---------------------------------------------------------------------------------------
# VG-ALPHA


@pytest.mark.spec("VG-ALPHA")
@DEVICE_SETTINGS
@given(splats(), st.integers(0, 2**32 - 1))
def test_splat_alpha_reference_vs_fast(device, args, seed):
    # Away from ALPHA_MIN and ALPHA_MAX: float32 would round across them.
    assume(alpha_margin(*args) > 1e-3)
    # Floor 1: alphas live in [0, 1]; float32 cannot represent what float64 calls tiny.
    # Observed over 300 random inputs: float64 <= 1.2e-16, float32 <= 1.9e-7.
    check_agreement(ref.splat_alpha, splat_alpha, args, diff=(0, 1, 2, 3), device=device, seed=seed, floor=1.0)
    check_float32(ref.splat_alpha, splat_alpha, args, device, floor=1.0)


@pytest.mark.spec("VG-ALPHA")
@pytest.mark.parametrize("dtype", DTYPES)
def test_splat_alpha_thresholds(device, dtype):
    # Unit conic, d = (1, 0): sigma = 1/2. Opacities put o exp(-sigma) 1% above and below
    # ALPHA_MIN, then one that clamps at ALPHA_MAX at d = 0.
    pixel = to_torch([[1.0, 0.0], [1.0, 0.0], [0.0, 0.0]], dtype, device)
    o = to_torch(ALPHA_MIN * np.exp(0.5) * np.array([1.01, 0.99, 1e3]), dtype, device, requires_grad=True)
    alpha = splat_alpha(pixel, torch.zeros_like(pixel), to_torch([1.0, 0.0, 1.0], dtype, device), o)
    np.testing.assert_allclose(to_numpy(alpha), [1.01 * ALPHA_MIN, 0.0, ALPHA_MAX], rtol=1e-6)
    # d alpha / d o = exp(-sigma) where unclamped; 0 where skipped or clamped.
    (g,) = torch.autograd.grad(alpha.sum(), o)
    np.testing.assert_allclose(to_numpy(g), [np.exp(-0.5), 0.0, 0.0], rtol=1e-6)


@pytest.mark.spec("VG-ALPHA")
@pytest.mark.parametrize("dtype", DTYPES)
def test_indefinite_conic_is_skipped_with_zero_gradient(device, dtype):
    # sigma = (1 + 1)/2 - 20 * 1 = -19 at d = (1, 1) and -1000-ish at d = (10, 10), where
    # o exp(-sigma) overflows: skipped, exactly 0, and no NaN in any gradient.
    inputs = [to_torch(x, dtype, device, requires_grad=True)
              for x in ([[1.0, 1.0], [10.0, 10.0]], [[0.0, 0.0], [0.0, 0.0]], [[1.0, -20.0, 1.0]] * 2, [0.5, 0.5])]
    alpha = splat_alpha(*inputs)
    assert torch.equal(alpha, torch.zeros_like(alpha))
    for g in torch.autograd.grad(alpha.sum(), inputs):
        assert torch.equal(g, torch.zeros_like(g))


@pytest.mark.spec("VG-ALPHA")
def test_splat_alpha_broadcasts(device):
    jj, ii = np.meshgrid(np.arange(4) + 0.5, np.arange(3) + 0.5)
    pixels = np.stack([jj, ii], -1)  # (3, 4, 2)
    mean2d, conic, opacity = np.array([1.0, 1.0]), np.array([0.5, 0.1, 0.4]), np.array(0.7)
    alpha = splat_alpha(*(to_torch(x, device=device) for x in (pixels, mean2d, conic, opacity)))
    assert alpha.shape == (3, 4)
    assert_close(alpha, ref.splat_alpha(pixels, mean2d, conic, opacity), RTOL64)


@pytest.mark.spec("VG-ALPHA")
def test_splat_alpha_gradcheck(device):
    # Alphas between 0.05 and 0.8: far from both thresholds within the probe steps.
    pixel = np.array([[1.0, 2.0], [3.5, 0.5], [2.0, 2.0]])
    mean2d = pixel + np.array([[0.5, -0.3], [-0.2, 0.4], [0.1, 0.1]])
    conic = np.array([[1.0, 0.2, 0.8], [0.6, -0.1, 1.2], [2.0, 0.5, 1.0]])
    opacity = np.array([0.5, 0.8, 0.3])
    gradcheck_fn(splat_alpha, (pixel, mean2d, conic, opacity), diff=(0, 1, 2, 3), device=device)


# ---------------------------------------------------------------------------------------
# VG-BLEND


@pytest.mark.spec("VG-BLEND")
@DEVICE_SETTINGS
@given(unit_colors, alphas_in_range, hnp.arrays(np.float64, 3, elements=st.floats(0.0, 1.0)),
       st.integers(0, 2**32 - 1))
def test_blend_reference_vs_fast(device, colors, alphas, background, seed):
    # Same multiplications in the same order: float64 agrees to the last bits, even on the
    # threshold. float32 rounds T by ~1e-7 relative: keep 0.1% away from TRANSMITTANCE_MIN.
    # Floor 1: colours and T live in [0, 1] (a background of 1e-90 underflows in float32).
    # Observed over 300 random inputs: float64 <= 1.2e-16, float32 <= 1.3e-7.
    check_agreement(ref.blend, blend, (colors, alphas, background), diff=(0, 1, 2), device=device, seed=seed,
                    floor=1.0)
    if transmittance_margin(alphas) > 1e-3:
        check_float32(ref.blend, blend, (colors, alphas, background), device, floor=1.0)


@pytest.mark.spec("VG-BLEND")
def test_skipped_splat_has_no_gradient(device):
    # alpha = 0 is "skipped" (VG-BLEND's `continue`), not a factor 1 - 0 of T: its gradient
    # is 0, as in the reference. A factor would give d color / d alpha_1 = -0.4 here.
    alphas = to_torch([0.5, 0.0, 0.5], device=device, requires_grad=True)
    color, T = blend(to_torch(np.eye(3), device=device), alphas, to_torch([0.1, 0.2, 0.3], device=device))
    (g,) = torch.autograd.grad(color.sum() + T, alphas)
    assert g[1] == 0.0 and g[0] != 0.0


@pytest.mark.spec("VG-BLEND")
@pytest.mark.parametrize("dtype", DTYPES)
def test_no_splats_show_the_background(device, dtype):
    bg = to_torch([0.1, 0.2, 0.3], dtype, device)
    color, T = blend(torch.zeros(0, 3, dtype=dtype, device=device), torch.zeros(0, dtype=dtype, device=device), bg)
    assert torch.equal(color, bg) and T == 1.0


@pytest.mark.spec("VG-BLEND")
def test_transmittance_exactly_at_the_minimum_is_still_blended(device):
    # The reference's case: T (1 - a3) rounds to exactly TRANSMITTANCE_MIN in float64, so
    # the third splat is blended (the stop is strict) and the fourth ends the pixel.
    a3 = 0.9782608695652174
    color, T = blend(to_torch(np.eye(4)[:, :3], device=device), to_torch([0.8, 0.977, a3, 0.5], device=device),
                     torch.zeros(3, dtype=torch.float64, device=device))
    assert T == TRANSMITTANCE_MIN
    np.testing.assert_allclose(to_numpy(color), [0.8, 0.2 * 0.977, 0.2 * 0.023 * a3], rtol=1e-12)


@pytest.mark.spec("VG-BLEND")
@DEVICE_SETTINGS
@given(unit_colors, alphas_in_range)
def test_weights_and_final_transmittance_sum_to_one(device, colors, alphas):
    # White splats over white: sum_i alpha_i T_i + T = 1, stopped early or not.
    ones = torch.ones(6, 3, dtype=torch.float64, device=device)
    color, T = blend(ones, to_torch(alphas, device=device), ones[0])
    torch.testing.assert_close(color, ones[0], rtol=0, atol=1e-12)
    assert T >= TRANSMITTANCE_MIN


@pytest.mark.spec("VG-BLEND")
def test_blend_gradcheck(device):
    rng = np.random.default_rng(6)
    # T falls to 0.7 * 0.9 * 0.3 ... 6e-3, far from the stop; no alpha = 0, where the
    # spec's skip makes blend discontinuous.
    alphas = np.array([0.3, 0.1, 0.7, 0.5, 0.9, 0.2])
    assert transmittance_margin(alphas) > 0.1
    gradcheck_fn(blend, (rng.uniform(size=(6, 3)), alphas, rng.uniform(size=3)), diff=(0, 1, 2), device=device)


# ---------------------------------------------------------------------------------------
# VG-RENDER against the reference


@st.composite
def render_scenes(draw, max_n=12, max_size=12):
    """Random scenes (render_cases.random_scene) with a background, all opacity regimes
    (faint to opaque, so ALPHA_MAX and the early stop occur), RGB or SH colours, and
    either rasterize mode."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    opacity = draw(st.sampled_from([(0.05, 0.6), (0.3, 1.0), (0.8, 1.0)]))
    sh_degree = draw(st.sampled_from([None, 0, 1, 3]))
    scene = random_scene(rng, draw(st.integers(1, max_n)), draw(st.integers(4, max_size)),
                         draw(st.integers(4, max_size)), scale_px=(0.5, 4.0), opacity=opacity, sh_degree=sh_degree)
    scene["background"] = rng.uniform(size=3)
    scene["mode"] = draw(st.sampled_from(RASTERIZE_MODES))
    if sh_degree is not None:
        scene["sh_degree"] = sh_degree
    return scene


@pytest.mark.spec("VG-RENDER")
@DEVICE_SETTINGS
@given(render_scenes())
def test_rasterize_reference_vs_fast(device, backend, scene):
    image_ref, alpha_ref, meta_ref = ref.rasterize(**scene)
    for dtype, delta, rtol in ((torch.float64, BAND64, RTOL64), (torch.float32, BAND32, RTOL32)):
        band = boundary_band(scene, delta)
        assume(band.mean() < 0.5)  # most of the image is compared
        # Observed outside the band over 150 random scenes: float64 <= 7e-16, float32 <= 5e-7.
        image, alpha, meta = rasterize(**scene_to_torch(scene, dtype, device), backend=backend)
        assert image.shape == image_ref.shape and alpha.shape == alpha_ref.shape
        assert image.dtype == alpha.dtype == dtype and image.device.type == device
        assert_close(image, image_ref, rtol, name=f"{dtype} image", mask=~band)
        assert_close(alpha, alpha_ref, rtol, name=f"{dtype} alpha", mask=~band)
        if dtype == torch.float64:
            assert meta["n_pairs"] == meta_ref["n_pairs"]
            for key in ("mean2d", "depth", "cov2d", "conic", "compensation", "colors"):
                assert_close(meta[key], meta_ref[key], rtol, name=key, floor=1.0)
            np.testing.assert_array_equal(meta["valid"].cpu().numpy(), meta_ref["valid"])


@pytest.mark.spec("VG-RENDER")
@settings(DEVICE_SETTINGS, max_examples=10)  # one reference VJP (~0.3 s through its per-pixel loop) each
@given(render_scenes(max_n=8, max_size=9), st.integers(0, 2**32 - 1))
def test_rasterize_gradients_reference_vs_fast(device, backend, scene, seed):
    # Band pixels get a zero cotangent: there the two may take different sides of a
    # threshold, elsewhere both differentiate the same smooth function.
    keep = ~boundary_band(scene, GRAD_BAND)[..., None]
    assume(keep.mean() > 0.5)
    rng = np.random.default_rng(seed)
    shape = (scene["height"], scene["width"])
    cot_image, cot_alpha = rng.standard_normal((*shape, 3)) * keep, rng.standard_normal((*shape, 1)) * keep
    g_ref = render_gradients(scene, cot_image, cot_alpha)
    g_fast = render_gradients(scene, cot_image, cot_alpha, device, backend)
    for key, g in g_ref.items():
        # Unit floor as in check_agreement; 1e-9 of the largest: the loss sums hundreds of
        # pairs, each a few roundings apart (observed <= 2e-14 over 80 random scenes).
        assert_close(g_fast[key], g, RTOL64, name=f"gradient of {key}", floor=1.0)


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("mode", RASTERIZE_MODES)
def test_rasterize_gradcheck(device, backend, mode):
    rng = np.random.default_rng(8)
    scene = random_scene(rng, 3, 6, 5, opacity=(0.3, 0.8))
    scene["background"] = rng.uniform(size=3)
    scene["mode"] = mode
    # Finite differences step 1e-6: no pixel within 1e-4 of a threshold.
    assert not boundary_band(scene, 1e-4).any()
    static = {k: to_torch(v, device=device) if isinstance(v, np.ndarray) else v
              for k, v in scene.items() if k not in RENDER_GRAD_KEYS}

    def render(*xs):
        image, alpha, _ = rasterize(**dict(zip(RENDER_GRAD_KEYS, xs)), **static, backend=backend)
        return image, alpha

    # fast_mode: one random projection of the 120 x 45 Jacobian instead of all of it.
    gradcheck_fn(render, [scene[k] for k in RENDER_GRAD_KEYS], diff=tuple(range(6)), device=device, fast_mode=True)


@pytest.mark.spec("VG-RENDER", "VG-BLEND")
def test_dense_opaque_scene_stops_early_like_the_reference(device, backend):
    # 16 opaque splats of 3-6 px over a 10 x 8 image: many pixels reach the early stop.
    rng = np.random.default_rng(9)
    scene = random_scene(rng, 16, 10, 8, scale_px=(3.0, 6.0), opacity=(0.9, 1.0))
    image_ref, alpha_ref, _ = ref.rasterize(**scene)
    band = boundary_band(scene, BAND64)
    assert band.mean() < 0.1
    image, alpha, _ = rasterize(**scene_to_torch(scene, torch.float64, device), backend=backend)
    assert_close(image, image_ref, RTOL64, mask=~band)
    assert_close(alpha, alpha_ref, RTOL64, mask=~band)
    # Pixels stopped early sit at T in [TRANSMITTANCE_MIN, TRANSMITTANCE_MIN / (1 - ALPHA_MAX)).
    T = 1 - to_numpy(alpha)
    assert np.all(T >= TRANSMITTANCE_MIN * (1 - 1e-9))
    assert np.sum(T < TRANSMITTANCE_MIN / (1 - ALPHA_MAX)) >= 10


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_entry_point_outputs(device, dtype):
    assert velogauss_fast.rasterize is rasterize
    rng = np.random.default_rng(10)
    scene = scene_to_torch(random_scene(rng, 4, 7, 5), dtype, device, requires_grad=True)
    image, alpha, meta = velogauss_fast.rasterize(**scene)
    assert image.shape == (5, 7, 3) and alpha.shape == (5, 7, 1)
    for key in ("mean2d", "depth", "cov2d", "conic", "radius", "valid", "colors", "n_pairs"):
        assert key in meta, key
    assert meta["radius"].dtype == torch.int64 and meta["valid"].dtype == torch.bool
    # Default background is black: the same scene over black + T * background.
    bg = torch.tensor([0.2, 0.5, 0.9], dtype=dtype, device=device)
    over, _, _ = velogauss_fast.rasterize(**scene, background=bg)
    torch.testing.assert_close(over, image + (1 - alpha) * bg)
    # The screen-space gradient used for densification is reachable through meta.
    meta["mean2d"].retain_grad()
    image.sum().backward()
    assert meta["mean2d"].grad is not None and torch.isfinite(meta["mean2d"].grad).all()


# ---------------------------------------------------------------------------------------
# The analytic backward, the transmittance and the chunking


def composite_inputs(scene, device):
    """Leaves (mean2d, conic, opacity, rgb, background) and the pair table of a float64 scene."""
    t = scene_to_torch(scene, torch.float64, device)
    proj = project_gaussians(t["means"], covariance_3d(t["quats"], t["scales"]), t["viewmat"], t["K"],
                             scene["width"], scene["height"])
    spans = row_spans(proj["mean2d"], proj["conic"], t["opacities"], proj["radius"], proj["depth"],
                              proj["valid"], scene["width"], scene["height"])
    pairs = pair_table(spans)
    leaves = [x.detach().clone().requires_grad_() for x in (proj["mean2d"], proj["conic"], t["opacities"],
                                                             t["colors"], to_torch(scene["background"], device=device))]
    return leaves, pairs


def composite_and_gradients(composite, leaves, pairs, seed):
    image, T = composite(*leaves, pairs)
    g = torch.Generator(device=image.device).manual_seed(seed)
    total = (image * torch.randn(image.shape, generator=g, dtype=image.dtype, device=image.device)).sum()
    total = total + (T * torch.randn(T.shape, generator=g, dtype=T.dtype, device=T.device)).sum()
    return (image, T), torch.autograd.grad(total, leaves)


@pytest.mark.spec("VG-BLEND", "VG-RENDER")
@pytest.mark.parametrize("chunk_pairs", [None, 400], ids=["one_chunk", "many_chunks"])
@pytest.mark.parametrize("seed", [0, 1])
def test_analytic_backward_matches_autograd(device, monkeypatch, chunk_pairs, seed):
    # 100 splats of 1.5-4 px on 20 x 16 px, every fifth fully opaque: runs of tens of
    # pairs, alphas clamped at ALPHA_MAX and thousands of pairs after an early stop.
    rng = np.random.default_rng(seed)
    scene = random_scene(rng, 100, 20, 16, scale_px=(1.5, 4.0), opacity=(0.5, 1.0))
    scene["opacities"][::5] = 1.0
    scene["background"] = rng.uniform(size=3)
    leaves, pairs = composite_inputs(scene, device)
    if chunk_pairs is not None:
        monkeypatch.setattr(compositing, "CHUNK_PAIRS", chunk_pairs)
        assert len(compositing.chunks(pairs.offsets, chunk_pairs)) > 10
    cols = compositing.gaussian_columns(*(x.detach() for x in leaves[:4]))
    centres = compositing.pixel_centres(scene["width"], scene["height"], torch.float64, device)
    alpha = compositing.pair_alpha(cols, centres, pairs.gid, pairs.pix)
    _, blended, _ = compositing.transmittance(alpha, pairs.offsets[1:] - pairs.offsets[:-1])
    assert ((alpha > 0) & ~blended).any() and (alpha == ALPHA_MAX).any()  # the cases are exercised

    out_a, grads_a = composite_and_gradients(compositing.Composite.apply, leaves, pairs, seed)
    out_b, grads_b = composite_and_gradients(compositing.composite_autograd, leaves, pairs, seed)
    # Forward: the same operations, bit for bit. Backward: the analytic one reassociates
    # per-pixel and per-Gaussian sums, then divides by 1 - alpha >= 0.01: observed <= 2e-14
    # of the largest entry (the opacity's, -s0 / o, the worst).
    for name, a, b in zip(("image", "T"), out_a, out_b):
        assert_close(a, to_numpy(b), 1e-13, name=name)
    for name, a, b in zip(("mean2d", "conic", "opacity", "rgb", "background"), grads_a, grads_b):
        assert_close(a, to_numpy(b), 1e-12, name=f"gradient of {name}", floor=1.0)


def exact_log_transmittance(alphas):
    """log prod_{j<i} (1 - alpha_j) for every i, from exact rational products of the floats."""
    out, prod = [], Fraction(1)
    for a in alphas:
        out.append(math.log(prod))
        prod *= 1 - Fraction(float(a))
    return np.array(out)


@pytest.mark.spec("VG-BLEND")
def test_transmittance_prefix_sums_are_exact_on_long_runs_in_a_full_chunk(device):
    # One chunk as long as CHUNK_PAIRS: 10^5 pixels of 10 opaque pairs (the chunk's sum of
    # |log(1 - alpha)| reaches 4.6e6, whose float64 ulp is 1e-9), then 5 pixels of 600
    # faint pairs whose T crosses TRANSMITTANCE_MIN near their end, between empty pixels.
    rng = np.random.default_rng(11)
    n_opaque, opaque_run, faint_run = 100_000, 10, 600
    faint = [rng.uniform(0.001, 0.03, faint_run) for _ in range(5)]
    alpha = np.concatenate([np.full(n_opaque * opaque_run, ALPHA_MAX), *faint])
    counts = np.concatenate([np.full(n_opaque, opaque_run), [0, faint_run, 0, faint_run, faint_run, 0, faint_run,
                                                             faint_run]])
    assert len(alpha) >= compositing.CHUNK_PAIRS * 0.95
    T, blended, _ = compositing.transmittance(to_torch(alpha, device=device), to_torch(counts, torch.int64, device))
    log_T, blended = np.log(to_numpy(T)), blended.cpu().numpy()

    exact = np.concatenate([np.tile(exact_log_transmittance(alpha[:opaque_run]), n_opaque),
                            *(exact_log_transmittance(a) for a in faint)])
    exact_next = exact + np.log1p(-alpha)  # log of T after each pair
    # Pairs that matter: T before them at least TRANSMITTANCE_MIN (the rest follow a stop).
    matter = exact >= math.log(TRANSMITTANCE_MIN)
    assert matter.sum() > 3 * n_opaque + 2000
    err = np.abs(log_T - exact)[matter]
    assert err.max() < LOG_T_ERROR, f"log T off by {err.max():.2e}"
    # The early stop, away from its threshold by more than that error.
    decided = np.abs(exact_next - math.log(TRANSMITTANCE_MIN)) > LOG_T_ERROR
    np.testing.assert_array_equal(blended[decided], (exact_next >= math.log(TRANSMITTANCE_MIN))[decided]
                                  & (exact >= math.log(TRANSMITTANCE_MIN))[decided])


@pytest.mark.spec("VG-RENDER", "VG-BLEND")
@pytest.mark.parametrize("which, chunk_pairs", [("torch", None), ("torch", 500), ("numba", None)],
                         ids=["torch-one_chunk", "torch-pixel_pairs_per_chunk", "numba"])
def test_hundreds_of_stacked_gaussians_match_the_reference(device, monkeypatch, which, chunk_pairs):
    # 300 faint Gaussians of 2-3 px, all covering a 3 x 2 image: every pixel composites a
    # run of 300 pairs and ends near TRANSMITTANCE_MIN (sum of log(1 - alpha) ~ -9). For
    # numba, whose backward recovers T by 300 divisions per pixel, the same bounds hold.
    if which == "numba" and device != "cpu":
        pytest.skip("numba is CPU only")
    if chunk_pairs is not None:
        monkeypatch.setattr(compositing, "CHUNK_PAIRS", chunk_pairs)  # chunks of two pixels
    rng = np.random.default_rng(12)
    n, K = 300, intrinsics(10.0, 10.0, 1.5, 1.0)
    z = rng.uniform(2.0, 8.0, n)
    means = in_view(rng.uniform([0.5, 0.5], [2.5, 1.5], (n, 2)), z, K)
    scales = rng.uniform(2.0, 3.0, (n, 3)) * z[:, None] / 10
    scene = {"means": means, "quats": rng.normal(size=(n, 4)), "scales": scales,
             "opacities": rng.uniform(0.01, 0.05, n), "colors": rng.uniform(size=(n, 3)), "viewmat": np.eye(4),
             "K": K, "width": 3, "height": 2, "background": np.array([0.3, 0.6, 0.9])}
    image_ref, alpha_ref, meta_ref = ref.rasterize(**scene)
    assert meta_ref["n_pairs"] == 6 * n
    band = boundary_band(scene, GRAD_BAND)
    assert band.sum() <= 1
    image, alpha, _ = rasterize(**scene_to_torch(scene, torch.float64, device), backend=which)
    assert_close(image, image_ref, RTOL64, mask=~band)
    log_T_err = np.abs(np.log1p(-to_numpy(alpha)) - np.log1p(-alpha_ref))[~band]
    assert log_T_err.max() < LOG_T_ERROR
    assert np.log1p(-alpha_ref).min() < -8.0  # the runs are long in log T too

    keep = ~band[..., None]
    cot_image, cot_alpha = rng.standard_normal((2, 3, 3)) * keep, rng.standard_normal((2, 3, 1)) * keep
    g_ref = render_gradients(scene, cot_image, cot_alpha)
    g_fast = render_gradients(scene, cot_image, cot_alpha, device, which)
    for key, g in g_ref.items():
        assert_close(g_fast[key], g, RTOL64, name=f"gradient of {key}", floor=1.0)

    image32, alpha32, _ = rasterize(**scene_to_torch(scene, torch.float32, device), backend=which)
    assert_close(image32, image_ref, RTOL32, mask=~band)
    assert_close(alpha32, alpha_ref, RTOL32, mask=~band)


@pytest.mark.spec("VG-RENDER")
def test_chunking_does_not_change_the_render(device, monkeypatch):
    rng = np.random.default_rng(13)
    scene = random_scene(rng, 40, 16, 12, scale_px=(1.0, 4.0), opacity=(0.2, 1.0))
    scene["background"] = rng.uniform(size=3)
    _, pairs = composite_inputs(scene, device)
    assert len(compositing.chunks(pairs.offsets, 97)) >= 10
    cot_image, cot_alpha = rng.standard_normal((12, 16, 3)), rng.standard_normal((12, 16, 1))
    t_scene = scene_to_torch(scene, torch.float64, device)

    def render():
        image, alpha, _ = rasterize(**t_scene, backend="torch")
        return image, alpha, render_gradients(scene, cot_image, cot_alpha, device, "torch")

    image, alpha, grads = render()
    monkeypatch.setattr(compositing, "CHUNK_PAIRS", 97)
    image_c, alpha_c, grads_c = render()
    # Only the float64 prefix sums' rounding depends on where chunks start: ~1e-16.
    assert_close(image_c, to_numpy(image), 1e-13)
    assert_close(alpha_c, to_numpy(alpha), 1e-13)
    for key, g in grads.items():
        assert_close(grads_c[key], g, 1e-12, name=f"gradient of {key}", floor=1.0)
