"""Image metrics: PSNR, SSIM and LPIPS v0.1 of a prediction against its ground truth.

spec/losses_metrics.md, VG-METRIC, VG-METRIC-SSIM, VG-METRIC-LPIPS. Images are H x W x 3
in [0, 1]. PSNR and SSIM are differentiable by autograd (SSIM is half of the photometric
loss, VG-LOSS); LPIPS is an evaluation metric written in plain NumPy, a literal
convolution network that reads its weights through `velogauss_core.lpips_nets`.
"""

import functools

import autograd.numpy as np
import numpy as onp
from numpy.lib.stride_tricks import sliding_window_view

from velogauss_core.checks import check_image_size
from velogauss_core.ssim_window import gaussian_window
from velogauss_ref.checks import check_array
from velogauss_core.constants import LPIPS_NORM_EPS, PSNR_MSE_FLOOR, SSIM_K1, SSIM_K2, SSIM_WINDOW
from velogauss_core.lpips_nets import LAYERS, SCALE, SHIFT, TAPS, check_net, min_image_size, read_weights, weights_file


def psnr(pred, gt):
    """Peak signal-to-noise ratio in dB: 10 log10(1 / max(MSE, PSNR_MSE_FLOOR)) (VG-METRIC).

    pred, gt: (H, W, 3), data range 1; MSE over all pixels and channels. Identical images
    give the cap of 100 dB (zero gradient there). Bad input raises ValueError naming it.
    """
    check_image_pair(pred, gt)
    mse = np.mean((pred - gt) ** 2)
    return 10.0 * np.log10(1.0 / np.maximum(mse, PSNR_MSE_FLOOR))


def ssim(pred, gt):
    """Mean structural similarity over channels and valid pixels (VG-METRIC-SSIM).

    pred, gt: (H, W, 3) with H, W >= SSIM_WINDOW (data range 1). Local means, population
    variances and covariance are correlations with the normalised SSIM_WINDOW^2 Gaussian
    window `gaussian_window()` (sigma SSIM_SIGMA) over the valid region only, an
    (H - 10) x (W - 10) map per channel; C1 = SSIM_K1^2, C2 = SSIM_K2^2. Equals
    scikit-image's structural_similarity(gaussian_weights=True, sigma=1.5,
    use_sample_covariance=False, data_range=1.0, channel_axis=-1). Symmetric in its
    arguments; 1 for identical images. Smaller images, mismatched shapes or non-finite
    values raise ValueError naming the argument.
    """
    check_image_pair(pred, gt, min_size=SSIM_WINDOW, why="the SSIM window")
    g = gaussian_window()
    mu_x, mu_y = _filter_valid(pred, g), _filter_valid(gt, g)
    var_x = _filter_valid(pred * pred, g) - mu_x * mu_x
    var_y = _filter_valid(gt * gt, g) - mu_y * mu_y
    cov_xy = _filter_valid(pred * gt, g) - mu_x * mu_y
    c1, c2 = SSIM_K1**2, SSIM_K2**2
    ssim_map = ((2 * mu_x * mu_y + c1) * (2 * cov_xy + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))
    return np.mean(ssim_map)



def _filter_valid(image, g):
    """Correlation of each channel of `image` (H, W, C) with the window g outer g, valid
    region only -> (H - k + 1, W - k + 1, C); separable: rows, then columns."""
    k = len(g)
    h, w = np.shape(image)[0] - k + 1, np.shape(image)[1] - k + 1
    rows = sum(g[i] * image[i:i + h] for i in range(k))
    return sum(g[j] * rows[:, j:j + w] for j in range(k))


def lpips(pred, gt, net="alex", weights_dir=None):
    """Learned perceptual image patch similarity, LPIPS v0.1 (VG-METRIC-LPIPS) -> float.

    pred, gt: (H, W, 3) in [0, 1], at least `min_image_size(net)` pixels (31 for alex, 16
    for vgg) in each direction; net: "alex" or "vgg"; weights_dir: folder of `<net>.npz`,
    or None for the resolution order of `velogauss_core.lpips_nets`.
    Each image goes to [-1, 1], then (x - SHIFT) / SCALE, through the backbone's layers;
    at each of the five taps (ReLU outputs) every pixel's channel vector is divided by its
    norm + LPIPS_NORM_EPS, the squared difference of the two images' vectors is weighted
    by the linear head, summed over channels and averaged over pixels; the five layer
    values are summed. Computed in float64. 0 for identical images.
    Raises ValueError naming `net`, `pred` or `gt` for bad input, FileNotFoundError when
    the weights cannot be found.
    """
    check_net(net)
    check_image_pair(pred, gt, min_size=min_image_size(net), why=f"LPIPS-{net}")
    path = weights_file(net, weights_dir)
    weights = _float64_weights(net, str(path), path.stat().st_mtime_ns)
    total = 0.0
    for k, (f_pred, f_gt) in enumerate(zip(_features(pred, net, weights), _features(gt, net, weights))):
        d = (_unit_channels(f_pred) - _unit_channels(f_gt)) ** 2  # (h, w, C)
        total += float(onp.mean(d @ weights[f"lin{k}.model.1.weight"].reshape(-1)))
    return total


@functools.lru_cache(maxsize=2)
def _float64_weights(net, path, mtime_ns):
    """The weights of `path` as float64 arrays, read once per file version (`mtime_ns`)."""
    return {k: v.astype(onp.float64) for k, v in read_weights(net, path).items()}


def _features(image, net, weights):
    """The backbone's activations (h, w, C) at the five TAPS of `net` for one image."""
    x = (2.0 * onp.asarray(image, dtype=onp.float64) - 1.0 - onp.array(SHIFT)) / onp.array(SCALE)
    taps = []
    for i, layer in enumerate(LAYERS[net]):
        if layer.kind == "conv":
            x = _conv2d(x, weights[f"features.{i}.weight"], weights[f"features.{i}.bias"], layer.stride, layer.padding)
        elif layer.kind == "relu":
            x = onp.maximum(x, 0.0)
        else:
            x = _max_pool(x, layer.kernel, layer.stride)
        if i in TAPS[net]:
            taps.append(x)
    return taps


def _conv2d(x, weight, bias, stride, padding):
    """torch's Conv2d on an (H, W, I) image: zero padding, cross-correlation with weight
    (O, I, k, k) at every `stride`-th position, plus bias (O,) -> (H', W', O)."""
    k = weight.shape[-1]
    padded = onp.pad(x, ((padding, padding), (padding, padding), (0, 0)))
    windows = sliding_window_view(padded, (k, k), axis=(0, 1))[::stride, ::stride]  # (H', W', I, k, k)
    return onp.tensordot(windows, weight, axes=([2, 3, 4], [1, 2, 3])) + bias


def _max_pool(x, kernel, stride):
    """torch's MaxPool2d (no padding, floor mode) on an (H, W, C) image."""
    return sliding_window_view(x, (kernel, kernel), axis=(0, 1))[::stride, ::stride].max(axis=(3, 4))


def _unit_channels(f):
    """lpips' normalize_tensor: each pixel's channel vector over (its norm + LPIPS_NORM_EPS)."""
    return f / (onp.sqrt(onp.sum(f * f, axis=-1, keepdims=True)) + LPIPS_NORM_EPS)


def check_image_pair(pred, gt, min_size=1, why=""):
    """Raise ValueError naming `pred`/`gt` unless both are finite (H, W, 3) images of one
    shape with H, W >= `min_size` (`why` names what needs that size)."""
    check_array("pred", pred, (None, None, 3))
    check_array("gt", gt, np.shape(pred))
    check_image_size(np.shape(pred), min_size, why)
