"""velogauss_fast.covariance: VG-COV against velogauss_ref.covariance."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fast.render_cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from velogauss_fast.covariance import covariance_3d
from velogauss_ref import covariance as ref

quats = hnp.arrays(np.float64, (5, 4), elements=st.floats(-2.0, 2.0)).filter(
    lambda q: np.all(np.sum(q * q, axis=-1) >= 0.01)
)
scales = hnp.arrays(np.float64, (5, 3), elements=st.floats(-3.0, 3.0))


@pytest.mark.spec("VG-COV")
@DEVICE_SETTINGS
@given(q=quats, s=scales, seed=st.integers(0, 2**32 - 1))
def test_covariance_reference_vs_fast(device, q, s, seed):
    check_agreement(ref.covariance_3d, covariance_3d, (q, s), diff=(0, 1), device=device, seed=seed)
    check_float32(ref.covariance_3d, covariance_3d, (q, s), device)


@pytest.mark.spec("VG-COV")
@DEVICE_SETTINGS
@given(q=quats, s=scales)
def test_covariance_is_symmetric_psd_with_eigenvalues_s_squared(device, q, s):
    Sigma = covariance_3d(torch.tensor(q, device=device), torch.tensor(s, device=device))
    assert torch.equal(Sigma, Sigma.transpose(-1, -2))
    eig = torch.linalg.eigvalsh(Sigma).cpu().numpy()
    np.testing.assert_allclose(eig, np.sort(s**2, axis=-1), rtol=0, atol=1e-12 * max(1.0, np.max(s**2)))


@pytest.mark.spec("VG-COV")
def test_zero_quaternion_gives_axis_aligned_covariance(device):
    q = torch.zeros(1, 4, dtype=torch.float64, device=device)
    s = torch.tensor([[1e-8, 2.0, 1e4]], dtype=torch.float64, device=device)
    assert torch.equal(covariance_3d(q, s)[0], torch.diag(s[0] ** 2))


@pytest.mark.spec("VG-COV")
def test_covariance_gradcheck(device):
    rng = np.random.default_rng(3)
    gradcheck_fn(covariance_3d, (rng.normal(size=(3, 4)), rng.uniform(0.1, 2.0, (3, 3))), diff=(0, 1), device=device)


@pytest.mark.parametrize(
    "q, s, name",
    [
        (torch.ones(2, 3), torch.ones(2, 3), "quats"),
        (torch.ones(2, 4), torch.ones(3, 3), "scales"),
        (torch.ones(2, 4), torch.ones(2, 3, dtype=torch.int64), "scales"),
        (np.ones((2, 4)), torch.ones(2, 3), "quats"),
    ],
)
def test_bad_input_names_the_argument(q, s, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        covariance_3d(q, s)
