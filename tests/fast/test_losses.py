"""velogauss_fast.losses: VG-LOSS, VG-LOSS-PHYS and VG-LOSS-MIX against velogauss_ref.losses."""

import functools

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.render_cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from tests.fast.test_metrics import summed
from tests.ref.test_losses import offset_pair
from velogauss_fast.losses import mixing_entropy_loss, photometric_loss, physics_loss
from velogauss_fast.metrics import ssim_target
from velogauss_ref import losses as ref

seeds = st.integers(0, 2**32 - 1)
sizes = st.integers(11, 24)
weights = st.floats(0.01, 2.0)


BACKENDS = ["torch", "numba"]


def photometric(backend):
    """photometric_loss through `backend`."""
    return functools.partial(photometric_loss, backend=backend)


def skip_numba_off_cpu(backend, device):
    if backend == "numba" and device != "cpu":
        pytest.skip("the numba photometric loss is CPU only")


@pytest.mark.spec("VG-LOSS")
@pytest.mark.parametrize("loss_backend", BACKENDS)
@DEVICE_SETTINGS
@given(seed=seeds, height=sizes, width=sizes)
def test_photometric_loss_reference_vs_fast(device, loss_backend, seed, height, width):
    skip_numba_off_cpu(loss_backend, device)
    pred, gt = offset_pair(seed, height, width)
    # float64: observed 8e-15 relative (SSIM's window sums in another order); RTOL64 1e-9.
    # The numba kernel gives gt no gradient: pred's only.
    check_agreement(summed(ref.photometric_loss), summed(photometric(loss_backend)), (pred, gt),
                    diff=(0, 1) if loss_backend == "torch" else (0,), device=device, seed=seed)
    # float32: observed 1e-5 relative over 300 random pairs (small losses); RTOL32 1e-4.
    check_float32(ref.photometric_loss, photometric(loss_backend), (pred, gt), device)


@pytest.mark.spec("VG-LOSS")
@pytest.mark.parametrize("loss_backend", BACKENDS)
def test_photometric_loss_gradcheck(device, loss_backend):
    # |pred - gt| >= 1e-2 >> gradcheck's eps. The smallest image and pred only, as in
    # tests/fast/test_metrics.py::test_ssim_gradcheck; gt's gradient is compared with the reference.
    skip_numba_off_cpu(loss_backend, device)
    pred, gt = offset_pair(5, 11, 11, margin=1e-2)
    gradcheck_fn(photometric(loss_backend), (pred, gt), diff=(0,), device=device)


@pytest.mark.spec("VG-LOSS")
@pytest.mark.parametrize("loss_backend", BACKENDS)
def test_photometric_loss_of_identical_images_is_zero_with_zero_gradient(device, loss_backend):
    skip_numba_off_cpu(loss_backend, device)
    gt = torch.rand(16, 12, 3, dtype=torch.float64, device=device)
    pred = gt.clone().requires_grad_()
    loss = photometric_loss(pred, gt, backend=loss_backend)
    loss.backward()
    # SSIM(x, x) = 1 up to the rounding of E[x^2] - mu^2 over C2; |x| has gradient 0 at 0.
    assert float(loss.detach()) == pytest.approx(0.0, abs=1e-12)
    assert float(pred.grad.abs().max()) <= 1e-12


@pytest.mark.spec("VG-LOSS")
@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_numba_photometric_loss_is_the_torch_one_at_training_size(dtype, rtol):
    # A 128 x 128 render against its training image with the kept SSIM target, as the loop
    # calls it; with and without a gradient. float64: both are the same formula (the window
    # sums in another order); float32: torch rounds every step, numba only its result.
    rng = np.random.default_rng(4)
    gt = torch.tensor(rng.uniform(size=(128, 128, 3)), dtype=dtype)
    pred0 = (gt + torch.tensor(rng.normal(scale=0.05, size=(128, 128, 3)), dtype=dtype)).clamp(0, 1)
    pred0[10:30, 40:90] = gt[10:30, 40:90]  # pred == gt: the L1 term's zero gradient
    target = ssim_target(gt)
    values, grads = {}, {}
    for backend in BACKENDS:
        pred = pred0.clone().requires_grad_()
        loss = photometric_loss(pred, gt, target, backend=backend)
        (grads[backend],) = torch.autograd.grad(loss, pred)
        values[backend] = float(loss.detach())
        assert loss.dtype == dtype and grads[backend].dtype == dtype
        with torch.no_grad():
            assert float(photometric_loss(pred0, gt, target, backend=backend)) == values[backend]
    assert values["numba"] == pytest.approx(values["torch"], rel=rtol)
    scale = float(grads["torch"].abs().max())
    assert float((grads["numba"] - grads["torch"]).abs().max()) <= rtol * scale


def test_photometric_backend_that_cannot_run_is_an_error():
    pred, gt = torch.rand(12, 12, 3), torch.rand(12, 12, 3, requires_grad=True)
    with pytest.raises(ValueError, match="^backend: 'numba' needs"):
        photometric_loss(pred, gt, backend="numba")
    with pytest.raises(ValueError, match="^backend: expected"):
        photometric_loss(pred, gt.detach(), backend="cuda")
    # "auto" with a gt that needs a gradient takes the torch form and gives it one.
    loss = photometric_loss(pred, gt)
    (g,) = torch.autograd.grad(loss, gt)
    assert float(g.abs().max()) > 0


@pytest.mark.spec("VG-LOSS-PHYS")
@DEVICE_SETTINGS
@given(seed=seeds, n=st.integers(0, 9), lambda_transport=weights, lambda_div=weights, with_div=st.booleans())
def test_physics_loss_reference_vs_fast(device, seed, n, lambda_transport, lambda_div, with_div):
    rng = np.random.default_rng(seed)
    r, div = rng.standard_normal((n, 3)), (rng.standard_normal(n) if with_div else None)
    args = (r, div, lambda_transport, lambda_div)
    # Sums of at most 27 squares: a few ulps; RTOL64 1e-9, RTOL32 1e-4.
    check_agreement(ref.physics_loss, physics_loss, args, diff=(0, 1) if with_div else (0,), device=device,
                    seed=seed)
    check_float32(ref.physics_loss, physics_loss, args, device)


@pytest.mark.spec("VG-LOSS-PHYS")
def test_physics_loss_gradcheck(device):
    rng = np.random.default_rng(6)
    gradcheck_fn(lambda r, div: physics_loss(r, div, 0.3, 0.7), (rng.standard_normal((5, 3)), rng.standard_normal(5)),
                 diff=(0, 1), device=device)


@pytest.mark.spec("VG-LOSS-MIX")
@DEVICE_SETTINGS
@given(seed=seeds, n=st.integers(0, 9), k=st.integers(2, 8), weight=weights, spread=st.floats(0.1, 30.0))
def test_mixing_entropy_reference_vs_fast(device, seed, n, k, weight, spread):
    rng = np.random.default_rng(seed)
    logits = spread * rng.standard_normal((n, k))  # spread 30: rows that are one-hot in float32
    # log_softmax against logits - logsumexp: a few ulps of the logits (|logits| up to ~100)
    # per term, so the scale is the weight's nats, as in float32 below: a nearly one-hot row's
    # entropy can sit far below that rounding (seen: 4.9e-8 off by 4.5e-16 at spread 19,
    # 1e-8 relative; its gradient likewise), and RTOL64 of the weight still fails any
    # formula error.
    check_agreement(ref.mixing_entropy_loss, mixing_entropy_loss, (logits, weight), diff=(0,), device=device,
                    seed=seed, floor=weight, grad_floor=weight)
    # float32: a nearly one-hot row has an entropy far below its terms' rounding (seen: 3.9e-4
    # off by 5.8e-8 at spread 20), so the scale is the weight's nats: RTOL32 of weight.
    check_float32(ref.mixing_entropy_loss, mixing_entropy_loss, (logits, weight), device, floor=weight)


@pytest.mark.spec("VG-LOSS-MIX")
def test_mixing_entropy_gradcheck(device):
    rng = np.random.default_rng(7)
    gradcheck_fn(lambda logits: mixing_entropy_loss(logits, 0.4), (2.0 * rng.standard_normal((4, 5)),), diff=(0,),
                 device=device)


@pytest.mark.spec("VG-LOSS-MIX")
def test_mixing_entropy_of_a_saturated_row_is_finite_with_finite_gradient(device):
    logits = torch.tensor([[0.0, 1e4, 0.0], [1.0, 1.0, 1.0]], dtype=torch.float32, device=device, requires_grad=True)
    loss = mixing_entropy_loss(logits, 1.0)
    loss.backward()
    assert float(loss.detach()) == pytest.approx(np.log(3.0) / 2, rel=1e-6)
    assert bool(torch.isfinite(logits.grad).all())


@pytest.mark.parametrize("logits, weight, name", [(torch.zeros(4), 1.0, "logits"),
                                                  (torch.zeros(2, 3), float("nan"), "weight")])
def test_mixing_entropy_bad_input_names_the_argument(logits, weight, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        mixing_entropy_loss(logits, weight)


@pytest.mark.parametrize(
    "args, name",
    [
        ((torch.zeros(4, 4), torch.zeros(4, 4, 3)), "pred"),
        ((torch.zeros(12, 12, 3), torch.zeros(12, 13, 3)), "gt"),
        ((torch.zeros(10, 12, 3), torch.zeros(10, 12, 3)), "pred"),
    ],
)
def test_photometric_bad_input_names_the_argument(args, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        photometric_loss(*args)


@pytest.mark.parametrize(
    "r, div, lt, ld, name",
    [
        (torch.zeros(3, 2), None, 0.1, 0.1, "r"),
        (np.zeros((3, 3)), None, 0.1, 0.1, "r"),
        (torch.zeros(3, 3), torch.zeros(2), 0.1, 0.1, "div"),
        (torch.zeros(3, 3), torch.zeros(3, dtype=torch.int64), 0.1, 0.1, "div"),
        (torch.zeros(3, 3), None, -0.1, 0.1, "lambda_transport"),
        (torch.zeros(3, 3), None, 0.1, float("inf"), "lambda_div"),
    ],
)
def test_physics_bad_input_names_the_argument(r, div, lt, ld, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        physics_loss(r, div, lt, ld)
