"""velogauss_ref.covariance: VG-COV, Sigma = R S S^T R^T."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from velogauss_ref.covariance import covariance_3d
from velogauss_ref.quaternion import quat_to_rotmat

# Identities of O(1) float64 values through a few products and an eigendecomposition.
TOL = 1e-12

quats = hnp.arrays(np.float64, (4, 4), elements=st.floats(-2.0, 2.0)).filter(
    lambda q: np.all(np.sum(q * q, axis=-1) >= 0.01)
)
scales = hnp.arrays(np.float64, (4, 3), elements=st.floats(0.05, 2.0))


@pytest.mark.spec("VG-COV")
def test_axis_aligned_and_rotated_values():
    s = np.array([[0.5, 2.0, 3.0], [0.5, 2.0, 3.0]])
    q = np.array([[1.0, 0.0, 0.0, 0.0], [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]])  # I, 90 deg about z
    Sigma = covariance_3d(q, s)
    np.testing.assert_allclose(Sigma[0], np.diag([0.25, 4.0, 9.0]), atol=TOL)
    # Rotating by 90 degrees about z swaps the x and y variances.
    np.testing.assert_allclose(Sigma[1], np.diag([4.0, 0.25, 9.0]), atol=TOL)


@pytest.mark.spec("VG-COV")
@given(quats, scales)
def test_symmetric_psd_with_eigenvalues_s_squared(q, s):
    Sigma = covariance_3d(q, s)
    assert Sigma.shape == (4, 3, 3)
    np.testing.assert_array_equal(Sigma, np.swapaxes(Sigma, -1, -2))
    scale = np.max(s * s)
    np.testing.assert_allclose(np.linalg.eigvalsh(Sigma), np.sort(s * s, axis=-1), atol=TOL * scale)


@pytest.mark.spec("VG-COV")
@given(quats, scales)
def test_eigenvectors_are_the_rotation_columns(q, s):
    # Sigma R e_k = s_k^2 R e_k: the Gaussian's axes are the columns of R.
    Sigma, R = covariance_3d(q, s), quat_to_rotmat(q)
    np.testing.assert_allclose(Sigma @ R, R * (s * s)[:, None, :], atol=TOL * np.max(s * s))


@pytest.mark.spec("VG-COV")
@given(quats, scales, st.integers(0, 2**32 - 1))
def test_covariance_3d_gradient(q, s, seed):
    check_grads_fd(covariance_3d, (q, s), (0, 1), np.random.default_rng(seed))


@pytest.mark.parametrize(
    "q, s, name",
    [
        (np.zeros((2, 3)), np.ones((2, 3)), "quats"),
        (np.full((2, 4), np.nan), np.ones((2, 3)), "quats"),
        (np.ones((2, 4)), np.ones((3, 3)), "scales"),
        (np.ones((2, 4)), np.array([[1.0, 1.0, np.inf], [1.0, 1.0, 1.0]]), "scales"),
    ],
)
def test_bad_input_names_the_argument(q, s, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        covariance_3d(q, s)
