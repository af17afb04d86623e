"""The mixing weights between the Gaussians: Shepard's interpolation of their own, in torch.

Twin of `velogauss_ref.motion.between` (spec/motion.md, VG-FIELD-GAUSS).
"""

import torch

from velogauss_core.constants import (GAUSSIAN_FIELD_CHUNK, GAUSSIAN_FIELD_DISTANCE_FLOOR, GAUSSIAN_FIELD_NEIGHBOURS,
                                      GAUSSIAN_FIELD_POWER)
from velogauss_fast.checks import check_array


def mixing_between(x, centres, weights, k=GAUSSIAN_FIELD_NEIGHBOURS, power=GAUSSIAN_FIELD_POWER):
    """m~(x) = sum over the k nearest centres i of kappa_i m_i (VG-FIELD-GAUSS).

    x: (M, 3) query points; centres: (N, 3) the Gaussians' positions; weights: (N, K) their
    mixing weights (rows of static Gaussians zero) -> (M, K). kappa_i = d_i^-power / sum_j
    d_j^-power over the min(k, N) nearest, d_i = max(|x - c_i|, GAUSSIAN_FIELD_DISTANCE_FLOOR);
    a tie at the k-th distance is broken either way. Queries go in chunks of
    GAUSSIAN_FIELD_CHUNK distances. No centres for a query raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_array("centres", centres, (None, 3))
    check_array("weights", weights, (centres.shape[0], None))
    if centres.shape[0] == 0 and x.shape[0] > 0:
        raise ValueError("centres: no Gaussians to take the mixing weights from")
    n = min(k, centres.shape[0])
    rows = max(1, GAUSSIAN_FIELD_CHUNK // max(1, 3 * centres.shape[0]))
    out = [_chunk(part, centres, weights, n, power) for part in x.split(rows)]
    return torch.cat(out) if out else weights.new_zeros((0, weights.shape[1]))


def _chunk(x, centres, weights, n, power):
    """mixing_between for one chunk of queries x (m, 3) -> (m, K)."""
    # Differences, not |x|^2 + |c|^2 - 2 x.c: that form loses the distance of a query on a
    # centre to cancellation (1e-4 in float32 instead of 0).
    squared = ((x[:, None, :] - centres[None]) ** 2).sum(-1)  # [m, N]
    # topk, 50x faster than a sort at 10^4 Gaussians, may break a tie at the k-th distance
    # either way (the spec leaves it open). The index set carries no gradient; the
    # distances gathered through it do.
    near = torch.topk(squared.detach(), n, dim=1, largest=False, sorted=False).indices  # [m, n]
    inverse = squared.gather(1, near).clamp_min(GAUSSIAN_FIELD_DISTANCE_FLOOR ** 2) ** (-power / 2)
    kappa = inverse / inverse.sum(1, keepdim=True)
    return torch.einsum("mn,mnk->mk", kappa, weights[near])
