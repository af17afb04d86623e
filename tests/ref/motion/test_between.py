"""velogauss_ref.motion.between: VG-FIELD-GAUSS, the mixing weights between the Gaussians."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import FD_STEP
from velogauss_core.constants import GAUSSIAN_FIELD_DISTANCE_FLOOR
from velogauss_ref.motion.between import mixing_between

seeds = st.integers(0, 2**32 - 1)
# The finite differences move every input by up to FD_STEP along a unit direction: a margin
# of 100 steps between the k-th and (k+1)-th distances keeps the neighbour set fixed.
MARGIN = 100 * FD_STEP


def _inputs(seed, m=3, n=7, k_patterns=4):
    rng = np.random.default_rng(seed)
    weights = rng.dirichlet(np.ones(k_patterns), n)
    return rng.uniform(-1, 1, (m, 3)), rng.uniform(-1, 1, (n, 3)), weights


def _gap(x, centres, k):
    """Smallest gap between the k-th and (k+1)-th squared distance over the queries, and the
    smallest distance (both must clear the probes' reach)."""
    d = np.sort(np.linalg.norm(x[:, None] - centres[None], axis=2), axis=1)
    return (d[:, k] - d[:, k - 1]).min(), d[:, 0].min()


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_shepard_weights_by_hand():
    # Query at the origin; centres at distances 1, 2 and 4 along the axes; k = 2, power 2:
    # kappa = (1, 1/4) / (5/4) = (0.8, 0.2) on the two nearest; the third does not count.
    x = np.zeros((1, 3))
    centres = np.array([[0.0, 2.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -4.0]])
    weights = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]])
    np.testing.assert_allclose(mixing_between(x, centres, weights, k=2, power=2), [[0.2, 0.8]], rtol=1e-14)
    # power 1: (1, 1/2) / (3/2); k beyond N takes every centre.
    np.testing.assert_allclose(mixing_between(x, centres, weights, k=2, power=1), [[1 / 3, 2 / 3]], rtol=1e-14)
    every = np.array([1 / 4, 1.0, 1 / 16]) / (21 / 16)
    np.testing.assert_allclose(mixing_between(x, centres, weights, k=10), [every @ weights], rtol=1e-14)


@pytest.mark.spec("VG-FIELD-GAUSS")
@given(seeds)
def test_a_query_on_a_gaussian_takes_its_own_weights(seed):
    x, centres, weights = _inputs(seed, n=9)
    nearest = np.sort(np.linalg.norm(centres[:, None] - centres[None], axis=2), axis=1)[:, 1].min()
    assume(nearest > 1e-2)  # the others at least 1e-2 away: their share is below (1e-6 / 1e-2)^2 each
    np.testing.assert_allclose(mixing_between(centres, centres, weights), weights, rtol=0, atol=1e-7)


@pytest.mark.spec("VG-FIELD-GAUSS")
@given(seeds, st.integers(1, 9))
def test_a_convex_combination_unchanged_by_the_order_of_the_gaussians(seed, k):
    x, centres, weights = _inputs(seed, m=5, n=9)
    assume(_gap(x, centres, min(k, 8))[0] > 1e-9 if k < 9 else True)
    out = mixing_between(x, centres, weights, k=k)
    np.testing.assert_allclose(out.sum(axis=1), 1.0, rtol=1e-12)  # rows of the simplex stay in it
    assert (out >= 0).all()
    order = np.random.default_rng(seed).permutation(9)
    np.testing.assert_allclose(mixing_between(x, centres[order], weights[order], k=k), out, rtol=1e-12, atol=1e-15)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_static_gaussians_lend_no_motion():
    # Rows of zeros (static Gaussians) pull the weights toward zero in proportion to their kappa.
    x = np.zeros((1, 3))
    centres = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    weights = np.array([[0.0, 1.0], [0.0, 0.0]])
    np.testing.assert_allclose(mixing_between(x, centres, weights), [[0.0, 0.5]], rtol=1e-14)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_the_distance_floor():
    # Two Gaussians on the query share it equally; a third beyond the floor has no say.
    x = np.zeros((1, 3))
    centres = np.array([[0.0, 0.0, 0.0], [GAUSSIAN_FIELD_DISTANCE_FLOOR / 2, 0.0, 0.0], [0.5, 0.0, 0.0]])
    weights = np.eye(3)
    np.testing.assert_allclose(mixing_between(x, centres, weights), [[0.5, 0.5, 0.0]], atol=1e-10)


@pytest.mark.spec("VG-FIELD-GAUSS")
@given(seeds, st.integers(1, 6), st.sampled_from([1, 2, 3]))
def test_mixing_between_gradient(seed, k, power):
    x, centres, weights = _inputs(seed)
    gap, nearest = _gap(x, centres, k)
    assume(gap > MARGIN and nearest > MARGIN)
    check_grads_fd(lambda x, c, w: mixing_between(x, c, w, k=k, power=power), (x, centres, weights), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


def test_bad_input_names_the_argument():
    x, centres, weights = _inputs(0)
    with pytest.raises(ValueError, match="^x:"):
        mixing_between(x[:, :2], centres, weights)
    with pytest.raises(ValueError, match="^centres:"):
        mixing_between(x, np.full_like(centres, np.nan), weights)
    with pytest.raises(ValueError, match="^weights:"):
        mixing_between(x, centres, weights[:3])
    with pytest.raises(ValueError, match="^centres: no Gaussians"):
        mixing_between(x, np.zeros((0, 3)), np.zeros((0, 4)))
    assert mixing_between(np.zeros((0, 3)), centres, weights).shape == (0, 4)
