"""The mixing weights between the Gaussians: Shepard's interpolation of their own, in torch.

Twin of `velogauss_ref.motion.between` (spec/motion.md, VG-FIELD-GAUSS).
"""

from typing import Literal, get_args

import torch
from scipy.spatial import cKDTree

from velogauss_core.constants import (GAUSSIAN_FIELD_CHUNK, GAUSSIAN_FIELD_DISTANCE_FLOOR, GAUSSIAN_FIELD_NEIGHBOURS,
                                      GAUSSIAN_FIELD_POWER)
from velogauss_fast.checks import check_array

# How the nearest centres are found: "tree" a k-d tree (scipy's, on the CPU), "topk" every
# (query, centre) distance in chunks of GAUSSIAN_FIELD_CHUNK then torch.topk (any device),
# "auto" the tree for CPU tensors. At 2,000 queries over 6,500 Gaussians the tree takes about
# a hundredth of the time.
Search = Literal["auto", "tree", "topk"]


def mixing_between(x, centres, weights, k=GAUSSIAN_FIELD_NEIGHBOURS, power=GAUSSIAN_FIELD_POWER, search="auto"):
    """m~(x) = sum over the k nearest centres i of kappa_i m_i (VG-FIELD-GAUSS).

    x: (M, 3) query points; centres: (N, 3) the Gaussians' positions; weights: (N, K) their
    mixing weights (rows of static Gaussians zero) -> (M, K). kappa_i = d_i^-power / sum_j
    d_j^-power over the min(k, N) nearest, d_i = max(|x - c_i|, GAUSSIAN_FIELD_DISTANCE_FLOOR);
    a tie at the k-th distance is broken either way. search: see `Search`. No centres for a
    query raises ValueError.
    """
    check_array("x", x, (None, 3))
    check_array("centres", centres, (None, 3))
    check_array("weights", weights, (centres.shape[0], None))
    if centres.shape[0] == 0 and x.shape[0] > 0:
        raise ValueError("centres: no Gaussians to take the mixing weights from")
    near = nearest_centres(x, centres, min(k, centres.shape[0]), search)  # [M, n]
    # Differences, not |x|^2 + |c|^2 - 2 x.c: that form loses the distance of a query on a
    # centre to cancellation (1e-4 in float32 instead of 0). The index set carries no
    # gradient; the distances through it do.
    squared = ((x[:, None, :] - centres[near]) ** 2).sum(-1)  # [M, n]
    inverse = squared.clamp_min(GAUSSIAN_FIELD_DISTANCE_FLOOR ** 2) ** (-power / 2)
    kappa = inverse / inverse.sum(1, keepdim=True)
    return torch.einsum("mn,mnk->mk", kappa, weights[near])


def nearest_centres(x, centres, n, search="auto"):
    """Indices (M, n) int64 of the n nearest centres (N, 3) of each query x (M, 3), each row
    ascending (so that the sums over them run in one order whatever the search), a tie at the
    n-th distance broken either way; n <= N. No gradient."""
    if search not in get_args(Search):
        raise ValueError(f"search: expected one of {get_args(Search)}, got {search!r}")
    if search == "tree" and x.device.type != "cpu":
        raise ValueError(f"search: 'tree' needs CPU tensors; got tensors on {x.device}")
    x, centres = x.detach(), centres.detach()
    if x.shape[0] == 0 or n == 0:
        return torch.zeros((x.shape[0], n), dtype=torch.int64, device=x.device)
    if search == "tree" or (search == "auto" and x.device.type == "cpu"):
        _, near = cKDTree(centres.double().numpy()).query(x.double().numpy(), k=n)
        near = torch.from_numpy(near.reshape(x.shape[0], n).astype("int64"))
    else:
        rows = max(1, GAUSSIAN_FIELD_CHUNK // max(1, 3 * centres.shape[0]))
        # topk, 50x faster than a sort at 10^4 Gaussians.
        near = torch.cat([torch.topk(((part[:, None, :] - centres[None]) ** 2).sum(-1), n, dim=1, largest=False,
                                     sorted=False).indices for part in x.split(rows)])
    return near.sort(1).values
