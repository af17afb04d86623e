"""Tests of velogauss/visualize.py: the ground truth | prediction | error frames and the MP4
that `velogauss render` writes by default."""

import imageio.v3 as iio
import matplotlib
import numpy as np
import pytest

from velogauss.io_utils import write_animation
from velogauss.visualize import ERROR_COLORMAP, ERROR_DISPLAY_MAX, comparison_image, error_image


def _pair(seed=0, shape=(8, 10, 3)):
    rng = np.random.default_rng(seed)
    return rng.random(shape), rng.random(shape)


def test_error_panel_is_the_mean_absolute_error_through_the_colormap():
    gt, pred = _pair()
    expected_error = np.abs(gt - pred).mean(axis=-1)
    panel = error_image(gt, pred)
    assert panel.shape == gt.shape
    cmap = matplotlib.colormaps[ERROR_COLORMAP]
    np.testing.assert_allclose(panel, cmap(np.clip(expected_error / ERROR_DISPLAY_MAX, 0, 1))[..., :3])
    # No error is the colormap's bottom colour everywhere; the lowest value never saturates.
    np.testing.assert_allclose(error_image(gt, gt), np.broadcast_to(cmap(0.0)[:3], gt.shape))


def test_comparison_image_puts_three_panels_side_by_side():
    gt, pred = _pair(shape=(64, 64, 3))
    image = comparison_image(gt, pred, time=0.9, future=True, max_time=0.75, label=False)
    # 64 px panels are enlarged 3x (nearest neighbour) to reach MIN_PANEL_HEIGHT = 192.
    assert image.shape == (192, 3 * 192, 3) and image.dtype == np.uint8
    to_u8 = lambda x: np.round(np.clip(x, 0, 1) * 255).astype(np.uint8)  # noqa: E731
    np.testing.assert_array_equal(image[::3, 0:192:3], to_u8(gt))
    np.testing.assert_array_equal(image[::3, 192:384:3], to_u8(pred))
    np.testing.assert_array_equal(image[::3, 384::3], to_u8(error_image(gt, pred)))


@pytest.mark.parametrize("future", [False, True])
def test_labelled_frame_marks_observed_or_future(future):
    gt, pred = _pair(shape=(64, 64, 3))
    image = comparison_image(gt, pred, time=0.9 if future else 0.5, future=future, max_time=0.75)
    assert image.shape[1] == 3 * 192 and image.shape[0] > 192
    # The time bar below the panels: filled red in the future, green while observed.
    bar = image[-6, 5].astype(int)
    assert (bar[0] > bar[1]) == future


def test_mp4_holds_every_frame(tmp_path):
    frames = [np.full((32, 48, 3), k / 5.0) for k in range(6)]
    write_animation(tmp_path / "s.mp4", frames, fps=8)
    video = iio.imread(tmp_path / "s.mp4", plugin="FFMPEG")
    assert video.shape == (6, 32, 48, 3)
    # H.264 is lossy; flat grey levels come back within a few counts.
    np.testing.assert_allclose(video.reshape(6, -1).mean(axis=1), [255 * k / 5.0 for k in range(6)], atol=3)
