"""velogauss_fast.metrics: PSNR, SSIM and LPIPS against velogauss_ref.metrics, scikit-image
and the official lpips values (VG-METRIC, VG-METRIC-SSIM, VG-METRIC-LPIPS)."""

import json
import os

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.render_cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn, to_torch
from tests.ref.test_metrics import LPIPS_ATOL, image_pair, needs_lpips_data, skimage_ssim
from velogauss_fast import metrics
from velogauss_fast.metrics import lpips, psnr, ssim
from velogauss_ref import metrics as ref
from velogauss_core.lpips_nets import CHECKOUT_DIR, min_image_size

seeds = st.integers(0, 2**32 - 1)
sizes = st.integers(11, 24)


def summed(fn):
    """fn times the number of values of its (H, W, 3) inputs: the mean becomes a sum, so
    per-pixel gradients are O(1), the scale check_agreement's unit gradient floor assumes."""
    return lambda pred, gt: fn(pred, gt) * (pred.shape[0] * pred.shape[1] * 3)


@pytest.mark.spec("VG-METRIC")
@DEVICE_SETTINGS
@given(seed=seeds, height=st.integers(1, 9), width=st.integers(1, 9))
def test_psnr_reference_vs_fast(device, seed, height, width):
    pred, gt = image_pair(seed, height, width)
    check_agreement(ref.psnr, psnr, (pred, gt), diff=(0, 1), device=device, seed=seed)
    check_float32(ref.psnr, psnr, (pred, gt), device)


@pytest.mark.spec("VG-METRIC")
def test_psnr_known_offset_and_cap(device):
    gt = torch.rand(6, 5, 3, dtype=torch.float64, device=device)
    # MSE = 0.01 exactly -> 20 dB; identical images hit the 100 dB cap exactly.
    assert float(psnr(gt + 0.1, gt)) == pytest.approx(20.0, abs=1e-10)
    assert float(psnr(gt, gt)) == 100.0
    assert float(psnr(gt + 1e-6, gt)) == pytest.approx(100.0, abs=1e-10)
    value = psnr(gt.float(), gt.float())
    assert value.dtype == torch.float32 and value.device.type == torch.device(device).type


@pytest.mark.spec("VG-METRIC")
def test_psnr_gradcheck(device):
    pred, gt = image_pair(1, 4, 5)
    gradcheck_fn(psnr, (pred, gt), diff=(0, 1), device=device)


@pytest.mark.spec("VG-METRIC-SSIM")
@DEVICE_SETTINGS
@given(seed=seeds, height=sizes, width=sizes, noise=st.floats(0.05, 0.5))
def test_ssim_reference_vs_fast(device, seed, height, width, noise):
    pred, gt = image_pair(seed, height, width, noise)
    # float64: observed 4e-16 relative (window sums in another order); RTOL64 = 1e-9.
    check_agreement(summed(ref.ssim), summed(ssim), (pred, gt), diff=(0, 1), device=device, seed=seed)
    # float32: observed 1.6e-7 relative over 300 random pairs; RTOL32 = 1e-4.
    check_float32(ref.ssim, ssim, (pred, gt), device)


@pytest.mark.spec("VG-METRIC-SSIM")
@pytest.mark.parametrize("shape", [(11, 11), (64, 80), (97, 33)])
def test_ssim_matches_scikit_image(device, shape):
    pred, gt = image_pair(7, *shape)
    expected = skimage_ssim(pred, gt)
    # float64: same sums in another order, 1e-12 as in tests/ref/test_metrics.py; float32:
    # rounding of the local statistics, observed below 3e-7.
    assert float(ssim(to_torch(pred, device=device), to_torch(gt, device=device))) == pytest.approx(expected, abs=1e-12)
    value32 = ssim(to_torch(pred, torch.float32, device), to_torch(gt, torch.float32, device))
    assert value32.dtype == torch.float32 and float(value32) == pytest.approx(expected, abs=1e-5)


@pytest.mark.spec("VG-METRIC-SSIM")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_ssim_of_flat_images_in_both_dtypes(device, dtype):
    # Every sigma is 0: SSIM = (2 a b + C1) / (a^2 + b^2 + C1). Uncentred float32 statistics
    # (E[x^2] - mu^2 over C2) were 1.6e-4 off here; centred ones are within 2e-7.
    a, b, c1 = 0.6, 0.5, 1e-4
    value = ssim(torch.full((24, 30, 3), a, dtype=dtype, device=device), torch.full((24, 30, 3), b, dtype=dtype,
                                                                                    device=device))
    assert float(value) == pytest.approx((2 * a * b + c1) / (a * a + b * b + c1), abs=1e-6)


@pytest.mark.spec("VG-METRIC-SSIM")
def test_ssim_gradcheck(device):
    # The smallest image (one window per channel) and pred only: gradcheck builds the full
    # Jacobian column by column; gt's gradient is compared with the reference above.
    pred, gt = image_pair(2, 11, 11)
    gradcheck_fn(ssim, (pred, gt), diff=(0,), device=device)


@pytest.fixture(scope="module")
def lpips_cases():
    pairs = np.load(CHECKOUT_DIR / "pairs.npz")
    reference = json.loads((CHECKOUT_DIR / "reference.json").read_text())["pairs"]
    return [(pairs[f"{row['pair']}_dist"], pairs[f"{row['pair']}_ref"], row) for row in reference]


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_lpips_equals_the_official_values(lpips_cases, net, device):
    # All 20 pairs in float32, the dtype evaluation uses; observed errors below 6e-8.
    assert len(lpips_cases) == 20
    with torch.no_grad():
        for dist, image, row in lpips_cases:
            value = lpips(to_torch(dist, torch.float32, device), to_torch(image, torch.float32, device), net=net)
            assert value.dtype == torch.float32
            assert float(value) == pytest.approx(row[f"lpips_{net}"], abs=LPIPS_ATOL), row["pair"]


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_lpips_reference_vs_fast(lpips_cases, net, device):
    # A 40 x 48 crop keeps the NumPy VGG cheap. float64: the same convolutions summed in
    # another order, observed 4e-15 relative; float32: observed 1e-7 relative.
    dist, image, _ = lpips_cases[5]
    pred, gt = dist[40:80, 30:78].astype(np.float64), image[40:80, 30:78].astype(np.float64)
    with torch.no_grad():
        check_agreement(lambda p, g: ref.lpips(p, g, net=net), lambda p, g: lpips(p, g, net=net), (pred, gt),
                        diff=(), device=device)
        check_float32(lambda p, g: ref.lpips(p, g, net=net), lambda p, g: lpips(p, g, net=net), (pred, gt), device)


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
def test_lpips_network_is_cached_per_file_version(tmp_path, monkeypatch):
    # A copy of alex.npz with every linear head doubled doubles LPIPS (it is linear in the
    # heads; powers of two scale exactly); rewriting the file with quadrupled heads is
    # noticed, and each version of the file is read once.
    with np.load(CHECKOUT_DIR / "alex.npz") as data:
        arrays = {k: data[k] for k in data.files}
    heads = [k for k in arrays if k.startswith("lin")]

    def write(factor, mtime_ns):
        np.savez(tmp_path / "alex.npz", **{**arrays, **{k: factor * arrays[k] for k in heads}})
        os.utime(tmp_path / "alex.npz", ns=(mtime_ns, mtime_ns))

    reads = []
    read_weights = metrics.read_weights
    monkeypatch.setattr(metrics, "read_weights", lambda *args: reads.append(args) or read_weights(*args))
    pred, gt = (torch.tensor(x) for x in image_pair(4, 32, 40))
    base = float(lpips(pred, gt, weights_dir=CHECKOUT_DIR))
    write(2.0, 10**18)
    assert [float(lpips(pred, gt, weights_dir=tmp_path)) for _ in range(3)] == pytest.approx([2 * base] * 3, rel=1e-12)
    write(4.0, 2 * 10**18)
    assert float(lpips(pred, gt, weights_dir=tmp_path)) == pytest.approx(4 * base, rel=1e-12)
    assert [str(path) for _, path in reads[-2:]] == [str(tmp_path / "alex.npz")] * 2
    assert len([1 for _, path in reads if str(path).startswith(str(tmp_path))]) == 2


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_min_image_size_is_what_torch_accepts(net):
    # At min_image_size the last tap is 1 x 1; one pixel less and torch's own layers fail.
    size = min_image_size(net)
    path = metrics.weights_file(net, CHECKOUT_DIR)
    params = metrics._network(net, str(path), path.stat().st_mtime_ns, torch.device("cpu"), torch.float32)
    assert metrics._features(torch.zeros(1, 3, size, size), net, params)[-1].shape[-2:] == (1, 1)
    with pytest.raises(RuntimeError):
        metrics._features(torch.zeros(1, 3, size - 1, size), net, params)
    with pytest.raises(ValueError, match=f"^pred: LPIPS-{net} needs images of at least {size} x {size}"):
        lpips(torch.zeros(size - 1, size + 5, 3), torch.zeros(size - 1, size + 5, 3), net=net)


@needs_lpips_data
@pytest.mark.spec("VG-METRIC-LPIPS")
def test_lpips_is_zero_for_identical_images(device):
    image = torch.rand(33, 35, 3, device=device)
    for net in ("alex", "vgg"):
        assert float(lpips(image, image.clone(), net=net)) == 0.0


def test_lpips_without_weights_names_the_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="weights_dir: LPIPS weights vgg.npz not found") as err:
        lpips(torch.zeros(32, 32, 3), torch.zeros(32, 32, 3), net="vgg", weights_dir=tmp_path)
    assert err.value.filename == str(tmp_path / "vgg.npz")


@pytest.mark.parametrize(
    "fn, pred, gt, kwargs, name",
    [
        (psnr, torch.zeros(4, 4), torch.zeros(4, 4), {}, "pred"),
        (psnr, np.zeros((4, 4, 3)), torch.zeros(4, 4, 3), {}, "pred"),
        (psnr, torch.zeros(4, 4, 3), torch.zeros(4, 5, 3), {}, "gt"),
        (psnr, torch.zeros(4, 4, 3), torch.zeros(4, 4, 3, dtype=torch.float64), {}, "gt"),
        (psnr, torch.zeros(4, 4, 3, dtype=torch.int64), torch.zeros(4, 4, 3, dtype=torch.int64), {}, "pred"),
        (ssim, torch.zeros(12, 12, 3), torch.zeros(12, 13, 3), {}, "gt"),
        (ssim, torch.zeros(10, 20, 3), torch.zeros(10, 20, 3), {}, "pred"),
        (ssim, torch.zeros(20, 10, 3), torch.zeros(20, 10, 3), {}, "pred"),
        (lpips, torch.zeros(32, 32, 3), torch.zeros(32, 32, 3), {"net": "squeeze"}, "net"),
        (lpips, torch.zeros(30, 64, 3), torch.zeros(30, 64, 3), {"net": "alex"}, "pred"),
    ],
)
def test_bad_input_names_the_argument(fn, pred, gt, kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        fn(pred, gt, **kwargs)


@pytest.mark.spec("VG-METRIC-SSIM")
def test_ssim_with_a_kept_target_is_the_five_map_convolution_to_the_last_bit(device):
    # The training loop computes each image's half of SSIM once (ssim_target) and convolves
    # only x, x^2, xy per step. The value and pred's gradient must be those of the five maps
    # x, y, x^2, y^2, xy in one depthwise convolution (the form before the split), bit for
    # bit, or every recorded training changes.
    from velogauss_core.constants import SSIM_K1, SSIM_K2
    from velogauss_core.ssim_window import gaussian_window

    def five_maps(p, gt):
        g = torch.as_tensor(gaussian_window(), dtype=p.dtype, device=p.device)
        x_mean, y_mean = p.detach().mean((0, 1))[:, None, None], gt.mean((0, 1))[:, None, None]
        x, y = p.permute(2, 0, 1) - x_mean, gt.permute(2, 0, 1) - y_mean
        maps = torch.cat([x, y, x * x, y * y, x * y])[None]
        col, row = g.view(1, 1, -1, 1).expand(15, 1, -1, 1), g.view(1, 1, 1, -1).expand(15, 1, 1, -1)
        mu_x, mu_y, xx, yy, xy = torch.nn.functional.conv2d(torch.nn.functional.conv2d(maps, col, groups=15), row,
                                                            groups=15)[0].split(3)
        var_x, var_y, cov = xx - mu_x * mu_x, yy - mu_y * mu_y, xy - mu_x * mu_y
        mu_x, mu_y = mu_x + x_mean, mu_y + y_mean
        c1, c2 = SSIM_K1**2, SSIM_K2**2
        return (((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x**2 + mu_y**2 + c1) * (var_x + var_y + c2))).mean()

    pred, gt = (torch.as_tensor(a, dtype=torch.float32, device=device) for a in image_pair(3, 40, 52))
    target = metrics.ssim_target(gt)
    results = []
    for fn in (five_maps, lambda p, gt: metrics.ssim(p, gt, target), metrics.ssim):
        p = pred.clone().requires_grad_()
        value = fn(p, gt)
        value.backward()
        results.append((value.detach(), p.grad))
    for value, grad in results[1:]:
        assert torch.equal(value, results[0][0]) and torch.equal(grad, results[0][1])
    with pytest.raises(ValueError, match="target"):
        metrics.ssim(pred, gt.clone(), target)
