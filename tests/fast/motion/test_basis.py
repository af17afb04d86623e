"""velogauss_fast.motion.basis: VG-BASIS (Phi(x) and A(w), b(w)) against velogauss_ref."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from tests.fast.motion.cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from velogauss_fast.motion.basis import affine_from_coefficients, basis_matrix
from velogauss_ref.motion import basis as ref

seeds = st.integers(0, 2**32 - 1)
shapes = st.sampled_from([(5,), (2, 3), (0,), ()])


@pytest.mark.spec("VG-BASIS")
def test_columns_are_the_paper_fields(device):
    x, y, z = 0.3, -1.2, 2.0
    Phi = basis_matrix(torch.tensor([x, y, z], dtype=torch.float64, device=device)).cpu().numpy()
    expected = np.array([
        [1, 0, 0, 0, z, -y, x, 0, 0, y, 0, z],
        [0, 1, 0, -z, 0, x, 0, y, 0, x, z, 0],
        [0, 0, 1, y, -x, 0, 0, 0, z, 0, y, x],
    ])
    np.testing.assert_array_equal(Phi, expected)


@pytest.mark.spec("VG-BASIS")
@DEVICE_SETTINGS
@given(seed=seeds)
def test_affine_form_and_its_parts(device, seed):
    rng = np.random.default_rng(seed)
    x = torch.tensor(rng.standard_normal((6, 3)), device=device)
    w = torch.tensor(rng.standard_normal((6, 12)), device=device)
    A, b = affine_from_coefficients(w)
    torch.testing.assert_close(basis_matrix(x) @ w[..., None], A @ x[..., None] + b[..., None], rtol=0, atol=1e-13)
    omega = w[:, 3:6]
    spin = 0.5 * (A - A.transpose(-1, -2))
    # Omega x = omega cross x; curl = 2 omega; divergence = w7 + w8 + w9; shear symmetric, trace-free.
    torch.testing.assert_close((spin @ x[..., None])[..., 0], torch.cross(omega, x, dim=-1), rtol=0, atol=1e-13)
    torch.testing.assert_close(A.diagonal(dim1=-2, dim2=-1).sum(-1), w[:, 6:9].sum(-1), rtol=0, atol=1e-13)
    shear_only = torch.cat([torch.zeros_like(w[:, :9]), w[:, 9:]], dim=-1)
    A_shear, _ = affine_from_coefficients(shear_only)
    torch.testing.assert_close(A_shear, A_shear.transpose(-1, -2), rtol=0, atol=0)
    assert float(A_shear.diagonal(dim1=-2, dim2=-1).abs().max()) == 0.0
    torch.testing.assert_close(b, w[:, :3], rtol=0, atol=0)


@pytest.mark.spec("VG-BASIS")
@DEVICE_SETTINGS
@given(seed=seeds, shape=shapes)
def test_reference_vs_fast(device, seed, shape):
    rng = np.random.default_rng(seed)
    x = rng.uniform(-3, 3, shape + (3,))
    w = rng.standard_normal(shape + (12,))
    check_agreement(ref.basis_matrix, basis_matrix, (x,), diff=(0,), device=device, seed=seed)
    check_agreement(ref.affine_from_coefficients, affine_from_coefficients, (w,), diff=(0,), device=device, seed=seed)
    check_float32(ref.basis_matrix, basis_matrix, (x,), device)
    check_float32(ref.affine_from_coefficients, affine_from_coefficients, (w,), device)


@pytest.mark.spec("VG-BASIS")
def test_gradcheck(device):
    rng = np.random.default_rng(0)
    gradcheck_fn(basis_matrix, (rng.standard_normal((3, 3)),), diff=(0,), device=device)
    gradcheck_fn(affine_from_coefficients, (rng.standard_normal((3, 12)),), diff=(0,), device=device)


@pytest.mark.spec("VG-BASIS")
def test_rejects_bad_input():
    with pytest.raises(ValueError, match="^x"):
        basis_matrix(torch.zeros(4, 2))
    with pytest.raises(ValueError, match="^x"):
        basis_matrix(torch.zeros(4, 3, dtype=torch.int64))
    with pytest.raises(ValueError, match="^w"):
        affine_from_coefficients(torch.zeros(4, 11))
