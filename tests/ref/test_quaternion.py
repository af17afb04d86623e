"""velogauss_ref.quaternion: VG-QUAT (rotation matrix) and VG-QUAT-MUL (Hamilton product)."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from velogauss_ref.quaternion import quat_multiply, quat_to_rotmat

# Agreement of exact identities evaluated in float64 (a handful of roundings of O(1) values).
TOL = 1e-12

coords = st.floats(-2.0, 2.0, allow_nan=False)


def quats(n):
    """(n, 4) quaternions with |q|^2 >= 0.01, far above QUAT_ZERO_NORM_SQ (no identity branch)."""
    return hnp.arrays(np.float64, (n, 4), elements=coords).filter(
        lambda q: np.all(np.sum(q * q, axis=-1) >= 0.01)
    )


@pytest.mark.spec("VG-QUAT")
def test_known_rotations():
    s = np.sqrt(0.5)
    # 90 degrees about z maps x -> y and y -> -x.
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    # 180 degrees about x flips y and z.
    Rx = np.diag([1.0, -1.0, -1.0])
    R = quat_to_rotmat(np.array([[1.0, 0, 0, 0], [s, 0, 0, s], [0.0, 1, 0, 0]]))
    np.testing.assert_allclose(R[0], np.eye(3), atol=TOL)
    np.testing.assert_allclose(R[1], Rz, atol=TOL)
    np.testing.assert_allclose(R[2], Rx, atol=TOL)


@pytest.mark.spec("VG-QUAT")
@given(quats(5))
def test_rotation_is_orthonormal_with_det_one(q):
    R = quat_to_rotmat(q)
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=TOL)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=TOL)


@pytest.mark.spec("VG-QUAT")
@given(quats(5), st.floats(0.1, 10.0))
def test_sign_and_norm_do_not_matter(q, c):
    R = quat_to_rotmat(q)
    np.testing.assert_allclose(quat_to_rotmat(-q), R, atol=TOL)
    np.testing.assert_allclose(quat_to_rotmat(c * q), R, atol=TOL)


@pytest.mark.spec("VG-QUAT")
def test_batch_shape():
    q = np.random.default_rng(0).normal(size=(2, 3, 4))
    R = quat_to_rotmat(q)
    assert R.shape == (2, 3, 3, 3)
    np.testing.assert_allclose(R[1, 2], quat_to_rotmat(q[1, 2]), atol=TOL)


@pytest.mark.spec("VG-QUAT")
@given(quats(3), st.integers(0, 2**32 - 1))
def test_quat_to_rotmat_gradient(q, seed):
    check_grads_fd(quat_to_rotmat, (q,), (0,), np.random.default_rng(seed))


@pytest.mark.spec("VG-QUAT-MUL")
def test_hamilton_units():
    one, i, j, k = np.eye(4)
    assert np.array_equal(quat_multiply(i, j), k)
    assert np.array_equal(quat_multiply(j, i), -k)
    assert np.array_equal(quat_multiply(j, k), i)
    assert np.array_equal(quat_multiply(k, i), j)
    assert np.array_equal(quat_multiply(i, i), -one)
    assert np.array_equal(quat_multiply(one, k), k)


@pytest.mark.spec("VG-QUAT-MUL", "VG-QUAT")
@given(quats(4), quats(4))
def test_product_composes_like_rotation_matrices(a, b):
    np.testing.assert_allclose(quat_to_rotmat(quat_multiply(a, b)), quat_to_rotmat(a) @ quat_to_rotmat(b), atol=TOL)


@pytest.mark.spec("VG-QUAT-MUL")
@given(quats(4), quats(4))
def test_product_is_not_normalised(a, b):
    # |a (x) b| = |a| |b|: the product keeps the norms (no renormalisation inside).
    np.testing.assert_allclose(
        np.linalg.norm(quat_multiply(a, b), axis=-1),
        np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1),
        rtol=TOL,
    )


@pytest.mark.spec("VG-QUAT-MUL")
def test_product_broadcasts():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(5, 4)), rng.normal(size=(4,))
    np.testing.assert_allclose(quat_multiply(a, b)[3], quat_multiply(a[3], b), atol=TOL)


@pytest.mark.spec("VG-QUAT-MUL")
@given(quats(3), quats(3), st.integers(0, 2**32 - 1))
def test_quat_multiply_gradient(a, b, seed):
    check_grads_fd(quat_multiply, (a, b), (0, 1), np.random.default_rng(seed))


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: quat_to_rotmat(np.array([1.0, np.nan, 0.0, 0.0])), "q"),
        (lambda: quat_to_rotmat(np.array([np.inf, 0.0, 0.0, 0.0])), "q"),
        (lambda: quat_to_rotmat(np.zeros((2, 3))), "q"),
        (lambda: quat_multiply(np.zeros(3), np.zeros(4)), "a"),
        (lambda: quat_multiply(np.zeros(4), np.array([0.0, 0.0, np.nan, 0.0])), "b"),
    ],
)
def test_bad_input_names_the_argument(call, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        call()
