"""velogauss_ref.metrics: VG-METRIC (PSNR), VG-METRIC-SSIM, VG-METRIC-LPIPS."""

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from skimage.metrics import structural_similarity

from tests.ref.gradcheck import check_grads_fd
from velogauss_core.constants import SSIM_K1
from velogauss_core.lpips_nets import CHECKOUT_DIR
from velogauss_ref.metrics import lpips, psnr, ssim

needs_lpips_data = pytest.mark.skipif(not (CHECKOUT_DIR / "reference.json").is_file(),
                                      reason=f"LPIPS weights and reference values not in {CHECKOUT_DIR}")

# The official lpips values are float32 computations printed to full precision; the
# reference (float64) differs from them by float32 rounding, observed below 6e-8.
LPIPS_ATOL = 1e-4
# Pairs of pairs.npz the NumPy VGG16 runs on (about 1 s each on two idle cores, against
# 0.1 s for AlexNet, which covers all 20): one per distortion, over four source images.
VGG_PAIRS = ("astronaut_noise", "chelsea_blur", "coffee_shift", "rocket_contrast")

# Finite-difference step of the SSIM gradient checks. SSIM's variances E[x^2] - mu^2
# cancel, which amplifies the rounding noise of the value about 1e3-fold (1 / C2), while a
# random unit direction over ~800 pixel values gives directional derivatives down to 2e-6:
# at the default step 1e-6 the rounding term reached 5e-5 relative. At 1e-3 (Richardson:
# truncation ~ h^4) the largest relative error over 200 seeds was 7e-9, against RTOL 1e-6.
SSIM_FD_STEP = 1e-3

sizes = st.integers(11, 20)
seeds = st.integers(0, 2**32 - 1)


def image_pair(seed, height, width, noise=0.2):
    """A ground truth in [0, 1] and a prediction: ground truth plus clipped Gaussian noise."""
    rng = np.random.default_rng(seed)
    gt = rng.uniform(size=(height, width, 3))
    return np.clip(gt + noise * rng.standard_normal(gt.shape), 0.0, 1.0), gt


def skimage_ssim(pred, gt):
    return structural_similarity(pred, gt, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
                                 data_range=1.0, channel_axis=-1)


@pytest.mark.spec("VG-METRIC")
@given(seeds, st.floats(1e-3, 0.2), st.sampled_from([-1.0, 1.0]))
def test_psnr_of_a_constant_offset(seed, offset, sign):
    gt = np.random.default_rng(seed).uniform(0.2, 0.8, (9, 7, 3))
    # MSE = offset^2 exactly, so PSNR = -20 log10(offset); float64 sums of 189 equal terms.
    assert psnr(gt + sign * offset, gt) == pytest.approx(-20 * math.log10(offset), abs=1e-10)


@pytest.mark.spec("VG-METRIC")
def test_psnr_is_capped_at_100_db():
    gt = np.random.default_rng(0).uniform(size=(5, 6, 3))
    assert psnr(gt, gt) == 100.0
    assert psnr(gt + 1e-6, gt) == pytest.approx(100.0, abs=1e-12)  # MSE 1e-12 < PSNR_MSE_FLOOR
    assert psnr(gt + 1e-4, gt) == pytest.approx(80.0, abs=1e-8)  # MSE 1e-8: not capped


@pytest.mark.spec("VG-METRIC")
@given(seeds, st.integers(2, 9), st.integers(2, 9))
def test_psnr_gradient(seed, height, width):
    pred, gt = image_pair(seed, height, width)
    check_grads_fd(psnr, (pred, gt), (0, 1), np.random.default_rng(seed))


@pytest.mark.spec("VG-METRIC-SSIM")
@given(seeds, sizes, sizes, st.floats(0.0, 0.5))
def test_ssim_matches_scikit_image(seed, height, width, noise):
    pred, gt = image_pair(seed, height, width, noise)
    # Observed differences: 4.4e-16 (different summation orders of the same window sums);
    # 1e-12 leaves 2000x headroom and fails any change of window, crop or variance.
    assert ssim(pred, gt) == pytest.approx(skimage_ssim(pred, gt), abs=1e-12)


@pytest.mark.spec("VG-METRIC-SSIM")
@given(seeds, sizes, sizes)
def test_ssim_is_symmetric_and_one_for_identical_images(seed, height, width):
    pred, gt = image_pair(seed, height, width)
    assert ssim(pred, gt) == pytest.approx(ssim(gt, pred), abs=1e-15)
    assert ssim(gt, gt) == pytest.approx(1.0, abs=1e-14)
    assert ssim(pred, gt) < 0.99


@pytest.mark.spec("VG-METRIC-SSIM")
def test_ssim_of_flat_images_is_the_luminance_term():
    # No structure: every sigma is 0, so SSIM = (2 a b + C1) / (a^2 + b^2 + C1). The
    # variances E[x^2] - mu^2 come out as rounding noise (~1e-16) over C2 = 9e-4: 1e-12.
    a, b = 0.3, 0.7
    c1 = SSIM_K1**2
    assert ssim(np.full((11, 14, 3), a), np.full((11, 14, 3), b)) == pytest.approx(
        (2 * a * b + c1) / (a * a + b * b + c1), abs=1e-12)


@pytest.mark.spec("VG-METRIC-SSIM")
@given(seeds)
def test_ssim_of_a_window_sized_image_is_one_weighted_window(seed):
    # 11 x 11 images have exactly one valid window: the SSIM formula with weights
    # exp(-r^2 / (2 * 1.5^2)) (normalised) over the whole image, written out directly.
    pred, gt = image_pair(seed, 11, 11)
    r = np.arange(-5, 6)
    w = np.exp(-(r[:, None] ** 2 + r[None, :] ** 2) / 4.5)
    w = (w / w.sum())[:, :, None]
    mx, my = (w * pred).sum((0, 1)), (w * gt).sum((0, 1))
    vx, vy = (w * (pred - mx) ** 2).sum((0, 1)), (w * (gt - my) ** 2).sum((0, 1))
    cxy = (w * (pred - mx) * (gt - my)).sum((0, 1))
    c1, c2 = 0.01**2, 0.03**2
    expected = np.mean((2 * mx * my + c1) * (2 * cxy + c2) / ((mx**2 + my**2 + c1) * (vx + vy + c2)))
    assert ssim(pred, gt) == pytest.approx(expected, abs=1e-12)


@pytest.mark.spec("VG-METRIC-SSIM")
@given(seeds, st.integers(11, 14), st.integers(11, 14))
def test_ssim_gradient(seed, height, width):
    pred, gt = image_pair(seed, height, width)
    check_grads_fd(ssim, (pred, gt), (0, 1), np.random.default_rng(seed), step=SSIM_FD_STEP)


@pytest.fixture(scope="module")
def lpips_cases():
    pairs = np.load(CHECKOUT_DIR / "pairs.npz")
    reference = json.loads((CHECKOUT_DIR / "reference.json").read_text())["pairs"]
    return {row["pair"]: (pairs[f"{row['pair']}_dist"], pairs[f"{row['pair']}_ref"], row) for row in reference}


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_lpips_equals_the_official_values(lpips_cases, net):
    names = list(lpips_cases) if net == "alex" else VGG_PAIRS
    assert len(lpips_cases) == 20 and set(names) <= set(lpips_cases)
    for name in names:
        dist, ref, row = lpips_cases[name]
        assert lpips(dist, ref, net=net) == pytest.approx(row[f"lpips_{net}"], abs=LPIPS_ATOL), name


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
def test_lpips_is_zero_for_identical_images_and_symmetric(lpips_cases):
    dist, ref = (image[32:96, 32:96] for image in lpips_cases["camera_noise"][:2])
    assert lpips(ref, ref) == 0.0
    assert lpips(dist, ref) == pytest.approx(lpips(ref, dist), rel=1e-12)
    assert lpips(dist, ref) > 0.01


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net, size", [("alex", 31), ("vgg", 16)])
def test_lpips_smallest_image(net, size):
    # alex: 11x11 stride-4 conv (pad 2) -> 7, pool 3/2 -> 3, pool 3/2 -> 1; smaller fails.
    # vgg: four 2x2 pools before relu5_3 need 16 pixels.
    pred, gt = image_pair(0, size, size + 3)
    assert lpips(pred, gt, net=net) > 0
    with pytest.raises(ValueError, match=f"^pred: LPIPS-{net} needs images of at least {size} x {size}"):
        lpips(pred[:size - 1], gt[:size - 1], net=net)


@pytest.mark.parametrize(
    "fn, pred, gt, kwargs, name",
    [
        (psnr, np.zeros((4, 4)), np.zeros((4, 4)), {}, "pred"),
        (psnr, np.zeros((4, 4, 3)), np.zeros((4, 5, 3)), {}, "gt"),
        (psnr, np.zeros((0, 4, 3)), np.zeros((0, 4, 3)), {}, "pred"),
        (psnr, np.full((4, 4, 3), np.nan), np.zeros((4, 4, 3)), {}, "pred"),
        (ssim, np.zeros((12, 12, 3)), np.full((12, 12, 3), np.inf), {}, "gt"),
        (ssim, np.zeros((10, 20, 3)), np.zeros((10, 20, 3)), {}, "pred"),
        (ssim, np.zeros((12, 12, 4)), np.zeros((12, 12, 4)), {}, "pred"),
        (lpips, np.zeros((32, 32, 3)), np.zeros((32, 32, 3)), {"net": "squeeze"}, "net"),
        (lpips, np.zeros((32, 32, 3)), np.zeros((32, 32, 3)), {"net": None}, "net"),
        (lpips, np.zeros((30, 64, 3)), np.zeros((30, 64, 3)), {"net": "alex"}, "pred"),
        (lpips, np.zeros((32, 32, 3)), np.zeros((32, 31, 3)), {}, "gt"),
    ],
)
def test_bad_input_names_the_argument(fn, pred, gt, kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        fn(pred, gt, **kwargs)
