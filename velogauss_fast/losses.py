"""Training losses in torch: photometric, physics and mixing entropy. Twin of `velogauss_ref.losses`.

spec/losses_metrics.md, VG-LOSS, VG-LOSS-PHYS and VG-LOSS-MIX. Results are 0-d tensors in the inputs'
dtype and on their device.
"""

from typing import Literal

import torch

from velogauss_fast.backends import numba_available
from velogauss_fast.checks import check_array
from velogauss_fast.metrics import checked_target, ssim
from velogauss_core.constants import LAMBDA_DSSIM
from velogauss_core.checks import check_weight


def photometric_loss(pred, gt, target=None, backend: Literal["auto", "torch", "numba"] = "auto"):
    """(1 - LAMBDA_DSSIM) mean|pred - gt| + LAMBDA_DSSIM (1 - SSIM(pred, gt)) (VG-LOSS).

    pred, gt: (H, W, 3) tensors with H, W >= SSIM_WINDOW; SSIM as in
    `velogauss_fast.metrics.ssim`, with `target` = `ssim_target(gt)` when the caller keeps
    it (the same numbers). The L1 term passes a zero gradient where pred == gt.
    backend: "torch" (the formula above in torch operations, any device), "numba" (value and
    gradient in one compiled pass, `backends.numba_photometric`; CPU, and no gradient to gt)
    or "auto": numba where it can run (CPU tensors, numba installed, gt without a gradient),
    else torch. The two differ by rounding only: numba works in float64 throughout.
    Bad input raises ValueError naming the argument.
    """
    if backend not in ("auto", "torch", "numba"):
        raise ValueError(f"backend: expected 'auto', 'torch' or 'numba', got {backend!r}")
    target = checked_target(pred, gt, target)  # validates pred and gt first
    numba_runs = pred.device.type == "cpu" and numba_available() and not gt.requires_grad
    if backend == "numba" and not numba_runs:
        raise ValueError(f"backend: 'numba' needs CPU tensors, the numba package and a gt without a gradient; "
                         f"got tensors on {pred.device}, gt.requires_grad={gt.requires_grad}")
    if backend != "torch" and numba_runs:
        from velogauss_fast.backends.numba_photometric import photometric_loss_numba

        return photometric_loss_numba(pred, gt, target)
    d_ssim = 1.0 - ssim(pred, gt, target)
    return (1.0 - LAMBDA_DSSIM) * (pred - gt).abs().mean() + LAMBDA_DSSIM * d_ssim


def physics_loss(r, div, lambda_transport, lambda_div):
    """lambda_transport mean_i |r_i|^2 + lambda_div mean_i div_i^2 (VG-LOSS-PHYS).

    r: (N, 3); div: (N,) or None (compressible scene: the second term is dropped);
    lambda_transport, lambda_div: finite numbers >= 0. N = 0 gives 0. Bad input raises
    ValueError naming the argument.
    """
    check_array("r", r, (None, 3))
    n = r.shape[0]
    if div is not None:
        check_array("div", div, (n,))
    check_weight("lambda_transport", lambda_transport)
    check_weight("lambda_div", lambda_div)
    count = max(n, 1)  # an empty sum over max(N, 1) is the 0 of "no particle"
    loss = lambda_transport * (r * r).sum() / count
    if div is not None:
        loss = loss + lambda_div * (div * div).sum() / count
    return loss


def mixing_entropy_loss(logits, weight):
    """weight · mean_i H(softmax(logits_i)), H(p) = −Σ_k p_k log p_k (VG-LOSS-MIX).

    logits: (N, K) mixing logits z A + c of VG-COEF; weight: finite number >= 0. The log
    weights come from log_softmax, so a saturated row (p_k = 0 in floating point) adds 0,
    not 0 · log 0 = NaN. N = 0 gives 0. Bad input raises ValueError naming the argument.
    """
    check_array("logits", logits, (None, None))
    check_weight("weight", weight)
    log_p = torch.log_softmax(logits, dim=-1)
    return weight * -(log_p.exp() * log_p).sum() / max(logits.shape[0], 1)
