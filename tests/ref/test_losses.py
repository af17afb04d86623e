"""velogauss_ref.losses: VG-LOSS (photometric), VG-LOSS-PHYS (physics) and VG-LOSS-MIX (mixing entropy)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.ref.gradcheck import check_grads_fd
from tests.ref.test_metrics import SSIM_FD_STEP, skimage_ssim
from velogauss_core.constants import LAMBDA_DSSIM
from velogauss_ref.losses import mixing_entropy_loss, photometric_loss, physics_loss

seeds = st.integers(0, 2**32 - 1)
sizes = st.integers(11, 14)


def offset_pair(seed, height, width, margin=2e-3):
    """A ground truth and a prediction differing by at least `margin` in every value, so
    that |pred - gt| is smooth within a finite-difference step of SSIM_FD_STEP."""
    rng = np.random.default_rng(seed)
    gt = rng.uniform(size=(height, width, 3))
    offset = rng.choice([-1.0, 1.0], gt.shape) * rng.uniform(margin, 0.3, gt.shape)
    return gt + offset, gt


@pytest.mark.spec("VG-LOSS")
@given(seeds, sizes, sizes)
def test_photometric_loss_is_weighted_l1_plus_dssim(seed, height, width):
    pred, gt = offset_pair(seed, height, width)
    expected = (1 - 0.2) * np.mean(np.abs(pred - gt)) + 0.2 * (1 - skimage_ssim(pred, gt))
    assert LAMBDA_DSSIM == 0.2
    # SSIM agrees with scikit-image to 4e-16 (tests/ref/test_metrics.py); L1 is exact.
    assert photometric_loss(pred, gt) == pytest.approx(expected, abs=1e-12)


@pytest.mark.spec("VG-LOSS")
def test_photometric_loss_of_flat_images():
    # Flat 0.5 vs 0.6: L1 = 0.1, SSIM = luminance term (0.6 + C1) / (0.61 + C1), C1 = 1e-4.
    loss = photometric_loss(np.full((12, 11, 3), 0.6), np.full((12, 11, 3), 0.5))
    assert loss == pytest.approx(0.8 * 0.1 + 0.2 * (1 - 0.6001 / 0.6101), abs=1e-12)
    assert photometric_loss(np.full((12, 11, 3), 0.5), np.full((12, 11, 3), 0.5)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.spec("VG-LOSS")
@given(seeds, sizes, sizes)
def test_photometric_loss_gradient(seed, height, width):
    pred, gt = offset_pair(seed, height, width)
    # SSIM's cancellation needs the larger step (see SSIM_FD_STEP); every |pred - gt| is
    # at least 2e-3, so the step never crosses the kink of the L1 term.
    check_grads_fd(photometric_loss, (pred, gt), (0, 1), np.random.default_rng(seed), step=SSIM_FD_STEP)


@pytest.mark.spec("VG-LOSS-PHYS")
def test_physics_loss_known_values():
    r = np.array([[1.0, 2.0, 2.0], [0.0, 0.0, 0.0]])  # |r|^2 = 9 and 0: mean 4.5
    div = np.array([3.0, -1.0])  # mean div^2 = 5
    assert physics_loss(r, div, 0.1, 0.01) == pytest.approx(0.45 + 0.05, abs=1e-15)
    assert physics_loss(r, None, 0.1, 0.01) == pytest.approx(0.45, abs=1e-15)
    assert physics_loss(r, div, 0.0, 0.0) == 0.0


@pytest.mark.spec("VG-LOSS-PHYS")
def test_physics_loss_without_particles_is_zero():
    assert physics_loss(np.zeros((0, 3)), np.zeros(0), 1.0, 1.0) == 0.0
    assert physics_loss(np.zeros((0, 3)), None, 1.0, 1.0) == 0.0


@pytest.mark.spec("VG-LOSS-PHYS")
@given(seeds, st.integers(1, 8), st.floats(0.01, 2.0), st.floats(0.01, 2.0))
def test_physics_loss_gradient(seed, n, lambda_transport, lambda_div):
    rng = np.random.default_rng(seed)
    r, div = rng.standard_normal((n, 3)), rng.standard_normal(n)
    check_grads_fd(lambda r, div: physics_loss(r, div, lambda_transport, lambda_div), (r, div), (0, 1), rng)


@pytest.mark.spec("VG-LOSS-MIX")
def test_mixing_entropy_known_values():
    # Even over K patterns: log K; all on one: 0; (1/2, 1/2, 0, ...): log 2. Any shift of a
    # row's logits leaves its softmax, and so its entropy, unchanged.
    k = 5
    even, one_hot = np.zeros((1, k)), np.array([[0.0, 800.0, 0.0, 0.0, 0.0]])
    pair = np.array([[3.0, 3.0, -900.0, -900.0, -900.0]])
    assert mixing_entropy_loss(even, 1.0) == pytest.approx(np.log(k), abs=1e-15)
    assert mixing_entropy_loss(one_hot, 1.0) == 0.0  # p = (0, 1, 0, 0, 0) exactly: 0, not NaN
    assert mixing_entropy_loss(pair, 1.0) == pytest.approx(np.log(2.0), abs=1e-15)
    assert mixing_entropy_loss(np.vstack([even, pair]) + 7.0, 0.5) == pytest.approx(0.25 * np.log(10.0), abs=1e-15)


@pytest.mark.spec("VG-LOSS-MIX")
def test_mixing_entropy_without_particles_is_zero():
    assert mixing_entropy_loss(np.zeros((0, 4)), 1.0) == 0.0


@pytest.mark.spec("VG-LOSS-MIX")
@given(seeds, st.integers(1, 6), st.integers(2, 6), st.floats(0.01, 2.0))
def test_mixing_entropy_gradient(seed, n, k, weight):
    rng = np.random.default_rng(seed)
    check_grads_fd(lambda logits: mixing_entropy_loss(logits, weight), (2.0 * rng.standard_normal((n, k)),), (0,), rng)


@pytest.mark.parametrize("logits, weight, name", [(np.zeros(4), 1.0, "logits"), (np.full((2, 3), np.nan), 1.0, "logits"),
                                                  (np.zeros((2, 3)), -1.0, "weight")])
def test_mixing_entropy_bad_input_names_the_argument(logits, weight, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        mixing_entropy_loss(logits, weight)


@pytest.mark.parametrize(
    "args, name",
    [
        ((np.zeros((4, 4)), np.zeros((4, 4, 3))), "pred"),
        ((np.zeros((12, 12, 3)), np.zeros((12, 13, 3))), "gt"),
        ((np.zeros((10, 12, 3)), np.zeros((10, 12, 3))), "pred"),
        ((np.full((12, 12, 3), np.nan), np.zeros((12, 12, 3))), "pred"),
    ],
)
def test_photometric_bad_input_names_the_argument(args, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        photometric_loss(*args)


@pytest.mark.parametrize(
    "r, div, lt, ld, name",
    [
        (np.zeros((3, 2)), None, 0.1, 0.1, "r"),
        (np.array([[0.0, np.inf, 0.0]]), None, 0.1, 0.1, "r"),
        (np.zeros((3, 3)), np.zeros(2), 0.1, 0.1, "div"),
        (np.zeros((3, 3)), np.array([0.0, np.nan, 0.0]), 0.1, 0.1, "div"),
        (np.zeros((3, 3)), None, -0.1, 0.1, "lambda_transport"),
        (np.zeros((3, 3)), None, 0.1, float("nan"), "lambda_div"),
        (np.zeros((3, 3)), None, np.ones(2), 0.1, "lambda_transport"),
    ],
)
def test_physics_bad_input_names_the_argument(r, div, lt, ld, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        physics_loss(r, div, lt, ld)
