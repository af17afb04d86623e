"""Training losses: the photometric loss of a rendered image, the physics loss and the
mixing weights' entropy.

spec/losses_metrics.md, VG-LOSS, VG-LOSS-PHYS and VG-LOSS-MIX. Differentiable by autograd.
"""

import autograd.numpy as np
from autograd.scipy.special import logsumexp

from velogauss_core.checks import check_weight
from velogauss_ref.checks import check_array
from velogauss_core.constants import LAMBDA_DSSIM
from velogauss_ref.metrics import ssim


def photometric_loss(pred, gt):
    """(1 - LAMBDA_DSSIM) mean|pred - gt| + LAMBDA_DSSIM (1 - SSIM(pred, gt)) (VG-LOSS).

    pred, gt: (H, W, 3) with H, W >= SSIM_WINDOW; SSIM as in `velogauss_ref.metrics.ssim`.
    The L1 term passes a zero gradient where pred == gt. Bad input raises ValueError
    naming the argument.
    """
    d_ssim = 1.0 - ssim(pred, gt)  # validates pred and gt first
    return (1.0 - LAMBDA_DSSIM) * np.mean(np.abs(pred - gt)) + LAMBDA_DSSIM * d_ssim


def physics_loss(r, div, lambda_transport, lambda_div):
    """lambda_transport mean_i |r_i|^2 + lambda_div mean_i div_i^2 (VG-LOSS-PHYS).

    r: (N, 3) transport residuals; div: (N,) divergences, or None for a compressible scene
    (the second term is dropped); lambda_transport, lambda_div: finite weights >= 0 (the
    training schedule ramps them from 0). N = 0 gives 0: no particle, no violation.
    Bad input raises ValueError naming the argument.
    """
    check_array("r", r, (None, 3))
    n = np.shape(r)[0]
    if div is not None:
        check_array("div", div, (n,))
    check_weight("lambda_transport", lambda_transport)
    check_weight("lambda_div", lambda_div)
    count = max(n, 1)  # an empty sum over max(N, 1) is the 0 of "no particle"
    loss = lambda_transport * np.sum(r * r) / count
    if div is not None:
        loss = loss + lambda_div * np.sum(div * div) / count
    return loss


def mixing_entropy_loss(logits, weight):
    """weight · mean_i H(softmax(logits_i)), H(p) = −Σ_k p_k log p_k (VG-LOSS-MIX).

    logits: (N, K) mixing logits z A + c of VG-COEF; weight: a finite weight >= 0. The
    entropy of one row is 0 when it puts all its weight on one pattern and log K when it
    spreads it evenly. log p = l − logsumexp(l), so a saturated row (p_k = 0 in floating
    point) adds 0, not 0 · log 0 = NaN. N = 0 gives 0. Bad input raises ValueError naming
    the argument.
    """
    check_array("logits", logits, (None, None))
    check_weight("weight", weight)
    log_p = logits - logsumexp(logits, axis=1, keepdims=True)
    return weight * -np.sum(np.exp(log_p) * log_p) / max(np.shape(logits)[0], 1)
