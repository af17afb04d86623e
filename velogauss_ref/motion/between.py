"""The mixing weights between the Gaussians: Shepard's interpolation of their own.

spec/motion.md, VG-FIELD-GAUSS.
"""

import autograd.numpy as np
import numpy as onp
from autograd.tracer import getval

from velogauss_core.constants import GAUSSIAN_FIELD_DISTANCE_FLOOR, GAUSSIAN_FIELD_NEIGHBOURS, GAUSSIAN_FIELD_POWER
from velogauss_ref.checks import check_array


def mixing_between(x, centres, weights, k=GAUSSIAN_FIELD_NEIGHBOURS, power=GAUSSIAN_FIELD_POWER):
    """m~(x) = sum over the k nearest centres i of kappa_i m_i (VG-FIELD-GAUSS).

    x: (M, 3) query points; centres: (N, 3) the Gaussians' positions; weights: (N, K) their
    mixing weights (rows of static Gaussians zero) -> (M, K). kappa_i = d_i^-power / sum_j
    d_j^-power over the neighbours, d_i = max(|x - c_i|, GAUSSIAN_FIELD_DISTANCE_FLOOR);
    min(k, N) neighbours; a tie at the k-th distance goes to the lower index here (the spec
    leaves it open). Non-finite or wrongly shaped input, or no centres for a query, raises
    ValueError.
    """
    check_array("x", x, (None, 3))
    check_array("centres", centres, (None, 3))
    check_array("weights", weights, (np.shape(centres)[0], None))
    if np.shape(centres)[0] == 0 and np.shape(x)[0] > 0:
        raise ValueError("centres: no Gaussians to take the mixing weights from")
    n = min(k, np.shape(centres)[0])
    rows = []
    for xm in x:
        squared = np.sum((centres - xm) ** 2, axis=1)  # [N]
        # The neighbours are chosen on the values (an index set has no derivative); the
        # weights are differentiated within that set. Squared distances: a square root
        # would have an infinite derivative at a query on a centre.
        near = onp.argsort(getval(squared), kind="stable")[:n]
        inverse = np.maximum(squared[near], GAUSSIAN_FIELD_DISTANCE_FLOOR ** 2) ** (-power / 2)
        rows.append(np.dot(inverse / np.sum(inverse), weights[near]))
    return np.stack(rows) if rows else np.zeros((0, np.shape(weights)[1]))
