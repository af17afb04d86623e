"""velogauss_ref.motion.basis: VG-BASIS, the 12 affine basis fields Phi(x) and A(w), b(w)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import affine_matrix, flat_outputs
from velogauss_core.motion import COLUMN_GROUPS
from velogauss_ref.motion.basis import affine_from_coefficients, basis_matrix

# Sums of a few O(1) float64 products.
TOL = 1e-13

points = hnp.arrays(np.float64, (6, 3), elements=st.floats(-3, 3))
coeffs = hnp.arrays(np.float64, (6, 12), elements=st.floats(-3, 3))
seeds = st.integers(0, 2**32 - 1)


@pytest.mark.spec("VG-BASIS")
def test_columns_are_the_paper_fields():
    x, y, z = 0.3, -1.2, 2.0
    expected = np.array([
        [1, 0, 0, 0, z, -y, x, 0, 0, y, 0, z],
        [0, 1, 0, -z, 0, x, 0, y, 0, x, z, 0],
        [0, 0, 1, y, -x, 0, 0, 0, z, 0, y, x],
    ])
    np.testing.assert_array_equal(basis_matrix(np.array([x, y, z])), expected)


@pytest.mark.spec("VG-BASIS")
@given(points, coeffs)
def test_phi_w_equals_affine_form(x, w):
    A, b = affine_from_coefficients(w)
    Phi_w = np.einsum("nik,nk->ni", basis_matrix(x), w)
    np.testing.assert_allclose(Phi_w, np.einsum("nij,nj->ni", A, x) + b, rtol=0, atol=TOL)
    # A(w) and b(w) against the matrix written out by hand from the spec.
    for n in range(len(w)):
        np.testing.assert_array_equal(A[n], affine_matrix(w[n]))
    np.testing.assert_array_equal(b, w[:, :3])


@pytest.mark.spec("VG-BASIS")
@given(points, coeffs)
def test_spin_curl_divergence_and_shear(x, w):
    A, _ = affine_from_coefficients(w)
    omega = w[:, 3:6]
    spin = 0.5 * (A - np.swapaxes(A, 1, 2))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", spin, x), np.cross(omega, x), rtol=0, atol=TOL)
    # curl v = (dv3/dy - dv2/dz, dv1/dz - dv3/dx, dv2/dx - dv1/dy) with grad v = A.
    curl = np.stack([A[:, 2, 1] - A[:, 1, 2], A[:, 0, 2] - A[:, 2, 0], A[:, 1, 0] - A[:, 0, 1]], axis=-1)
    np.testing.assert_allclose(curl, 2 * omega, rtol=0, atol=TOL)
    np.testing.assert_allclose(np.trace(A, axis1=1, axis2=2), w[:, 6:9].sum(-1), rtol=0, atol=TOL)
    shear = np.concatenate([np.zeros((len(w), 9)), w[:, 9:]], axis=1)
    A_shear, b_shear = affine_from_coefficients(shear)
    np.testing.assert_array_equal(A_shear, np.swapaxes(A_shear, 1, 2))
    np.testing.assert_array_equal(np.trace(A_shear, axis1=1, axis2=2), 0.0)
    np.testing.assert_array_equal(b_shear, 0.0)


@pytest.mark.spec("VG-BASIS")
def test_column_groups_partition_the_columns_by_effect():
    assert sorted(i for cols in COLUMN_GROUPS.values() for i in cols) == list(range(12))
    x = np.array([0.4, -0.7, 1.1])
    Phi = basis_matrix(x)
    np.testing.assert_array_equal(Phi[:, list(COLUMN_GROUPS["translation"])], np.eye(3))
    omega = np.array([0.2, -1.0, 0.5])
    np.testing.assert_allclose(Phi[:, list(COLUMN_GROUPS["rotation"])] @ omega, np.cross(omega, x), atol=TOL)
    np.testing.assert_array_equal(Phi[:, list(COLUMN_GROUPS["stretch"])], np.diag(x))
    # Shear moves x by a symmetric, trace-free matrix.
    A = np.zeros((3, 3))
    for k in COLUMN_GROUPS["shear"]:
        e = np.zeros(12)
        e[k] = 1.0
        A_k, _ = affine_from_coefficients(e)
        np.testing.assert_array_equal(Phi[:, k], A_k @ x)
        A += A_k
    np.testing.assert_array_equal(A, A.T)
    assert np.trace(A) == 0.0


@pytest.mark.spec("VG-BASIS")
@pytest.mark.parametrize("batch", [(), (2, 3), (0,)])
def test_batch_shapes(batch):
    rng = np.random.default_rng(0)
    x, w = rng.standard_normal(batch + (3,)), rng.standard_normal(batch + (12,))
    Phi = basis_matrix(x)
    A, b = affine_from_coefficients(w)
    assert Phi.shape == batch + (3, 12) and A.shape == batch + (3, 3) and b.shape == batch + (3,)
    if batch == (2, 3):
        np.testing.assert_array_equal(Phi[1, 2], basis_matrix(x[1, 2]))
        np.testing.assert_array_equal(A[1, 2], affine_from_coefficients(w[1, 2])[0])


@pytest.mark.spec("VG-BASIS")
@given(points, coeffs, seeds)
def test_gradients(x, w, seed):
    rng = np.random.default_rng(seed)
    check_grads_fd(basis_matrix, (x,), (0,), rng)
    check_grads_fd(flat_outputs(affine_from_coefficients), (w,), (0,), rng)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: basis_matrix(np.zeros((4, 2))), "x"),
        (lambda: basis_matrix(np.array([[0.0, np.inf, 0.0]])), "x"),
        (lambda: affine_from_coefficients(np.zeros((4, 11))), "w"),
        (lambda: affine_from_coefficients(np.full(12, np.nan)), "w"),
    ],
)
def test_bad_input_names_the_argument(call, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        call()
