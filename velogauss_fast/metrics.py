"""Image metrics in torch: PSNR, SSIM and LPIPS v0.1. Twin of `velogauss_ref.metrics`.

spec/losses_metrics.md, VG-METRIC, VG-METRIC-SSIM, VG-METRIC-LPIPS. Images are H x W x 3
tensors in [0, 1]; results are 0-d tensors in the inputs' dtype and on their device.
SSIM is in the training loop (VG-LOSS): two depthwise 1D convolutions over the maps x, x^2,
xy of each channel, and once per training image over y, y^2 (`ssim_target`). LPIPS builds its network from the `.npz` weights once per
(net, weights file, device, dtype) and keeps it.
"""

import functools
from typing import NamedTuple

import torch
import torch.nn.functional as F

from velogauss_fast.checks import check_array
from velogauss_core.constants import LPIPS_NORM_EPS, PSNR_MSE_FLOOR, SSIM_K1, SSIM_K2, SSIM_WINDOW
from velogauss_core.lpips_nets import LAYERS, SCALE, SHIFT, TAPS, check_net, min_image_size, read_weights, weights_file
from velogauss_core.checks import check_image_size
from velogauss_core.ssim_window import gaussian_window


def psnr(pred, gt):
    """Peak signal-to-noise ratio in dB: 10 log10(1 / max(MSE, PSNR_MSE_FLOOR)) (VG-METRIC).

    pred, gt: (H, W, 3), data range 1. Identical images give the 100 dB cap (zero
    gradient there). Bad input raises ValueError naming the argument.
    """
    check_image_pair(pred, gt)
    mse = torch.mean((pred - gt) ** 2)
    return 10.0 * torch.log10(1.0 / mse.clamp_min(PSNR_MSE_FLOOR))


class SSIMTarget(NamedTuple):
    """What SSIM needs of the ground truth `gt (H, W, 3)` (`ssim_target`): its channel means
    (3, 1, 1) and the window's statistics of it centred on them, mu_y and y^2, (3, H - 10, W - 10)."""

    gt: torch.Tensor
    mean: torch.Tensor
    mu: torch.Tensor
    sq: torch.Tensor


def ssim_target(gt):
    """The ground truth's half of SSIM (VG-METRIC-SSIM), computed once for a training image
    that many steps compare with: `ssim(pred, gt, ssim_target(gt))` equals `ssim(pred, gt)` to
    the last bit (each depthwise convolution channel is computed on its own). gt: (H, W, 3),
    H, W >= SSIM_WINDOW (a gt that requires grad keeps its graph in the target)."""
    check_image_pair(gt, gt, min_size=SSIM_WINDOW, why="the SSIM window")
    return _target(gt)


def _target(gt):
    """`ssim_target` of a checked gt."""
    mean = gt.detach().mean((0, 1))[:, None, None]  # a constant shift: see `ssim`
    y = gt.permute(2, 0, 1) - mean
    mu, sq = _window_statistics(torch.cat([y, y * y]), gt).split(3)
    return SSIMTarget(gt, mean, mu, sq)


def ssim(pred, gt, target=None):
    """Mean structural similarity over channels and valid pixels (VG-METRIC-SSIM).

    pred, gt: (H, W, 3) with H, W >= SSIM_WINDOW. The statistics of
    `velogauss_ref.metrics.ssim` (11 x 11 Gaussian window, sigma 1.5, valid region,
    population variances), the window applied as a column then a row convolution.
    target: `ssim_target(gt)`, when the caller keeps it (the training loop, per image); None
    computes it here. Differentiable in pred; smaller images, mismatched shapes or non-finite
    values raise ValueError naming the argument.
    """
    target = checked_target(pred, gt, target)
    # Variances and covariance are invariant under a constant shift of x or y, and the
    # form E[x^2] - mu^2 cancels catastrophically in float32 (flat regions came out 1e-4
    # off in SSIM, the error divided by C2 = 9e-4): centre each channel on its mean first,
    # and add the means back to mu. The shift is a constant of the formula, hence detached.
    x_mean, y_mean = pred.detach().mean((0, 1))[:, None, None], target.mean
    x, y = pred.permute(2, 0, 1) - x_mean, target.gt.permute(2, 0, 1) - y_mean  # (3, H, W)
    mu_x, xx, xy = _window_statistics(torch.cat([x, x * x, x * y]), pred).split(3)  # of the centred images
    mu_y, yy = target.mu, target.sq
    var_x, var_y, cov_xy = xx - mu_x * mu_x, yy - mu_y * mu_y, xy - mu_x * mu_y
    mu_x, mu_y = mu_x + x_mean, mu_y + y_mean
    c1, c2 = SSIM_K1**2, SSIM_K2**2
    ssim_map = ((2 * mu_x * mu_y + c1) * (2 * cov_xy + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))
    return ssim_map.mean()


def checked_target(pred, gt, target):
    """`target`, or `ssim_target(gt)` when it is None, once pred and gt are checked as SSIM
    takes them; ValueError naming the argument otherwise (a target of another image too)."""
    check_image_pair(pred, gt, min_size=SSIM_WINDOW, why="the SSIM window")
    if target is None:
        return _target(gt)
    if target.gt is not gt:
        raise ValueError("target: expected ssim_target(gt) of this gt")
    return target


def _window_statistics(maps, like):
    """The Gaussian window's correlation over the valid region of each map of `maps (C, H, W)`
    -> (C, H - 10, W - 10), in `like`'s dtype and device. One depthwise (grouped) convolution
    per direction: on the CPU, forward and backward, about 20x faster at 400 x 400 than the
    same filter over a batch of single channels."""
    g = torch.as_tensor(gaussian_window(), dtype=like.dtype, device=like.device)
    n = maps.shape[0]
    return F.conv2d(F.conv2d(maps[None], g.view(1, 1, -1, 1).expand(n, 1, -1, 1), groups=n),
                    g.view(1, 1, 1, -1).expand(n, 1, 1, -1), groups=n)[0]


def lpips(pred, gt, net="alex", weights_dir=None):
    """Learned perceptual image patch similarity, LPIPS v0.1 (VG-METRIC-LPIPS).

    pred, gt: (H, W, 3) in [0, 1], at least `min_image_size(net)` pixels (31 for alex, 16
    for vgg) each way; net: "alex" or "vgg"; weights_dir: folder of `<net>.npz`, or None
    for the resolution order of `velogauss_core.lpips_nets`. The computation of
    `velogauss_ref.metrics.lpips` with torch's conv2d / max_pool2d, both images in one
    batch. Differentiable except where a tapped feature vector is exactly zero (the
    norm's derivative is undefined there); meant for evaluation, under torch.no_grad().
    Raises ValueError naming `net`, `pred` or `gt` for bad input, FileNotFoundError when
    the weights cannot be found.
    """
    check_net(net)
    check_image_pair(pred, gt, min_size=min_image_size(net), why=f"LPIPS-{net}")
    path = weights_file(net, weights_dir)
    params = _network(net, str(path), path.stat().st_mtime_ns, pred.device, pred.dtype)
    shift = torch.tensor(SHIFT, dtype=pred.dtype, device=pred.device)
    scale = torch.tensor(SCALE, dtype=pred.dtype, device=pred.device)
    x = ((2 * torch.stack([pred, gt]) - 1 - shift) / scale).permute(0, 3, 1, 2)  # (2, 3, H, W)
    total = pred.new_zeros(())
    for k, f in enumerate(_features(x, net, params)):
        f = f / (torch.sqrt(torch.sum(f * f, dim=1, keepdim=True)) + LPIPS_NORM_EPS)
        d = (f[0] - f[1]) ** 2  # (C, h, w)
        total = total + torch.mean(F.conv2d(d[None], params[f"lin{k}.model.1.weight"]))
    return total


@functools.lru_cache(maxsize=8)
def _network(net, path, mtime_ns, device, dtype):
    """The weights of `path` as tensors on `device` in `dtype`; `mtime_ns` keys the cache so
    that a rewritten file is read again."""
    return {k: torch.as_tensor(v).to(device=device, dtype=dtype) for k, v in read_weights(net, path).items()}


def _features(x, net, params):
    """The backbone's activations (B, C, h, w) at the five TAPS of `net`."""
    taps = []
    for i, layer in enumerate(LAYERS[net]):
        if layer.kind == "conv":
            x = F.conv2d(x, params[f"features.{i}.weight"], params[f"features.{i}.bias"], layer.stride, layer.padding)
        elif layer.kind == "relu":
            x = F.relu(x)
        else:
            x = F.max_pool2d(x, layer.kernel, layer.stride)
        if i in TAPS[net]:
            taps.append(x)
    return taps


def check_image_pair(pred, gt, min_size=1, why=""):
    """Raise ValueError naming `pred`/`gt` unless both are finite (H, W, 3) tensors of one
    shape, dtype and device with H, W >= `min_size` (`why` names what needs that size)."""
    check_array("pred", pred, (None, None, 3))
    check_array("gt", gt, tuple(pred.shape))
    if gt.dtype != pred.dtype or gt.device != pred.device:
        raise ValueError(f"gt: expected dtype {pred.dtype} on {pred.device} like pred, got {gt.dtype} on {gt.device}")
    check_image_size(tuple(pred.shape), min_size, why)
