"""velogauss_fast.motion.between: VG-FIELD-GAUSS (Shepard's interpolation of the Gaussians'
mixing weights) against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import assume, given
from hypothesis import strategies as st

from tests.fast.motion.cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn, to_torch
from velogauss_fast.motion import between
from velogauss_ref.motion import between as ref


def _inputs(seed, m, n, k_patterns=5):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (m, 3)), rng.uniform(-1, 1, (n, 3)), rng.dirichlet(np.ones(k_patterns), n)


def _clear_gap(x, centres, k, margin):
    """The k-th and (k+1)-th distances of every query differ by more than `margin` (a tie
    there may go either way, and a probe must not cross one)."""
    d = np.sort(np.linalg.norm(x[:, None] - centres[None], axis=2), axis=1)
    return k >= centres.shape[0] or bool((d[:, k] - d[:, k - 1]).min() > margin)


@pytest.mark.spec("VG-FIELD-GAUSS")
@DEVICE_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), m=st.sampled_from([0, 1, 6]), n=st.sampled_from([1, 5, 12]),
       k=st.integers(1, 9), power=st.sampled_from([1, 2, 3]))
def test_reference_vs_fast(device, seed, m, n, k, power):
    x, centres, weights = _inputs(seed, m, n)
    assume(m == 0 or _clear_gap(x, centres, k, 1e-6))
    args = (x, centres, weights, k, power)
    # With one neighbour (k = 1 or N = 1) kappa = 1 whatever x: the gradients in x and the
    # centres vanish identically, and both sides return rounding noise of ~1e-17; the
    # gradients are O(1), so they are compared at that scale (an error of 1e-9 absolute).
    check_agreement(ref.mixing_between, between.mixing_between, args, diff=(0, 1, 2), device=device, seed=seed,
                    grad_floor=1.0)
    check_float32(ref.mixing_between, between.mixing_between, args, device)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_chunks_give_the_whole(monkeypatch):
    # The topk search (any device) over 40 queries and 30 centres, in chunks of 2 queries
    # (2 * 3 * 30 distances each).
    x, centres, weights = (torch.tensor(a) for a in _inputs(3, 40, 30))
    whole = between.mixing_between(x, centres, weights, search="topk")
    monkeypatch.setattr(between, "GAUSSIAN_FIELD_CHUNK", 180)
    assert len(x.split(max(1, between.GAUSSIAN_FIELD_CHUNK // (3 * 30)))) == 20
    torch.testing.assert_close(between.mixing_between(x, centres, weights, search="topk"), whole, rtol=0, atol=0)


@pytest.mark.spec("VG-FIELD-GAUSS")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("seed, m, n, k", [(8, 200, 1000, 8), (7, 50, 7, 8), (7, 20, 40, 1)])
def test_tree_and_topk_find_the_same_neighbours(dtype, seed, m, n, k):
    # The k-d tree (the CPU's default) and the chunked topk find the same neighbour sets
    # wherever the k-th and (k+1)-th distances are apart, and so the same weights to the
    # last bit (the distances are then computed by the same operations).
    x, centres, weights = _inputs(seed, m, n)
    assert _clear_gap(x, centres, k, 1e-4)  # far above float32's rounding of the distances
    x, centres, weights = (torch.tensor(a, dtype=dtype) for a in (x, centres, weights))
    near = {s: between.nearest_centres(x, centres, min(k, n), s).sort(1).values for s in ("tree", "topk")}
    assert torch.equal(near["tree"], near["topk"])
    out = {s: between.mixing_between(x, centres, weights, k, search=s) for s in ("tree", "topk", "auto")}
    assert torch.equal(out["tree"], out["topk"]) and torch.equal(out["auto"], out["tree"])


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_tree_search_needs_cpu_tensors_and_a_known_name(device):
    x, centres, _ = (torch.tensor(a, device=device) for a in _inputs(0, 3, 5))
    with pytest.raises(ValueError, match="^search: expected one of"):
        between.nearest_centres(x, centres, 2, "kd")
    if device != "cpu":
        with pytest.raises(ValueError, match="^search: 'tree' needs CPU tensors"):
            between.nearest_centres(x, centres, 2, "tree")


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_float32_query_on_a_mean_is_exact(device):
    # The distances are differences, not |x|^2 + |c|^2 - 2 x.c, whose cancellation leaves a
    # query on a centre 1e-4 away in float32 and would share its weight with the neighbours.
    rng = np.random.default_rng(0)
    centres = torch.tensor(rng.uniform(-3, 3, (200, 3)), dtype=torch.float32, device=device)
    weights = torch.softmax(torch.tensor(rng.standard_normal((200, 8)), dtype=torch.float32, device=device), -1)
    torch.testing.assert_close(between.mixing_between(centres, centres, weights), weights, rtol=0, atol=1e-6)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_gradcheck(device):
    x, centres, weights = _inputs(1, 4, 9)
    assert _clear_gap(x, centres, 8, 1e-3)
    gradcheck_fn(between.mixing_between, (x, centres, weights), diff=(0, 1, 2), device=device)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_rejects_bad_input():
    x, centres, weights = (to_torch(a) for a in _inputs(0, 3, 5))
    with pytest.raises(ValueError, match="^x:"):
        between.mixing_between(x[:, :2], centres, weights)
    with pytest.raises(ValueError, match="^weights:"):
        between.mixing_between(x, centres, weights[:2])
    with pytest.raises(ValueError, match="^centres: no Gaussians"):
        between.mixing_between(x, centres[:0], weights[:0])
    assert between.mixing_between(x[:0], centres, weights).shape == (0, 5)
