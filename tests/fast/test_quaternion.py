"""velogauss_fast.quaternion: VG-QUAT and VG-QUAT-MUL against velogauss_ref.quaternion."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fast.render_cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn
from velogauss_fast.quaternion import quat_multiply, quat_to_rotmat
from velogauss_ref import quaternion as ref
from velogauss_core.constants import QUAT_ZERO_NORM_SQ

coords = st.floats(-2.0, 2.0, allow_nan=False)


def quats(shape):
    """Quaternions with |q|^2 >= 0.01: far from QUAT_ZERO_NORM_SQ, so float32 and float64
    take the same branch (the threshold itself is pinned by the tests below)."""
    return hnp.arrays(np.float64, shape, elements=coords).filter(lambda q: np.all(np.sum(q * q, axis=-1) >= 0.01))


@pytest.mark.spec("VG-QUAT")
@DEVICE_SETTINGS
@given(q=quats((5, 4)), seed=st.integers(0, 2**32 - 1))
def test_quat_to_rotmat_reference_vs_fast(device, q, seed):
    check_agreement(ref.quat_to_rotmat, quat_to_rotmat, (q,), diff=(0,), device=device, seed=seed)
    check_float32(ref.quat_to_rotmat, quat_to_rotmat, (q,), device)


@pytest.mark.spec("VG-QUAT")
def test_quat_to_rotmat_batch_dims_and_dtype(device):
    q = np.random.default_rng(0).normal(size=(2, 3, 4))
    R = quat_to_rotmat(torch.tensor(q, dtype=torch.float32, device=device))
    assert R.shape == (2, 3, 3, 3) and R.dtype == torch.float32 and R.device.type == device
    np.testing.assert_allclose(R.cpu().numpy(), ref.quat_to_rotmat(q), atol=1e-6)


@pytest.mark.spec("VG-QUAT")
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_zero_and_denormal_quaternions_give_identity_with_zero_gradient(device, dtype):
    # |q|^2 = 0, 1e-26 and ~1e-80 (a float32 denormal whose square underflows) are below
    # QUAT_ZERO_NORM_SQ; |q|^2 = 1e-20 is above it and is normalised like any other.
    q = torch.tensor([[0.0, 0.0, 0.0, 0.0], [1e-13, 0.0, 0.0, 0.0], [0.0, 1e-40, 0.0, 0.0], [0.0, 0.0, 0.0, 1e-10]],
                     dtype=dtype, device=device, requires_grad=True)
    assert float((q[:3] ** 2).sum(-1).max()) < QUAT_ZERO_NORM_SQ < float((q[3] ** 2).sum())
    R = quat_to_rotmat(q)
    eye = torch.eye(3, dtype=dtype, device=device)
    assert torch.equal(R[:3], eye.expand(3, 3, 3))
    # q = (0, 0, 0, 1e-10) normalises to a rotation by 180 degrees about z.
    torch.testing.assert_close(R[3], torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=dtype, device=device)))
    (g,) = torch.autograd.grad((R * torch.randn_like(R)).sum(), q)
    assert torch.equal(g[:3], torch.zeros_like(g[:3]))
    assert torch.isfinite(g).all()


@pytest.mark.spec("VG-QUAT")
def test_quat_to_rotmat_gradcheck(device):
    q = np.random.default_rng(1).normal(size=(4, 4))
    gradcheck_fn(quat_to_rotmat, (q,), diff=(0,), device=device)


@pytest.mark.spec("VG-QUAT-MUL")
@DEVICE_SETTINGS
@given(a=quats((4, 4)), b=quats((4, 4)), seed=st.integers(0, 2**32 - 1))
def test_quat_multiply_reference_vs_fast(device, a, b, seed):
    check_agreement(ref.quat_multiply, quat_multiply, (a, b), diff=(0, 1), device=device, seed=seed)
    check_float32(ref.quat_multiply, quat_multiply, (a, b), device)


@pytest.mark.spec("VG-QUAT", "VG-QUAT-MUL")
@DEVICE_SETTINGS
@given(a=quats((4, 4)), b=quats((4, 4)))
def test_product_composes_rotations(device, a, b):
    ta, tb = (torch.tensor(x, device=device) for x in (a, b))
    torch.testing.assert_close(quat_to_rotmat(quat_multiply(ta, tb)), quat_to_rotmat(ta) @ quat_to_rotmat(tb),
                               rtol=0, atol=1e-12)


@pytest.mark.spec("VG-QUAT-MUL")
def test_quat_multiply_broadcasts(device):
    a = torch.tensor([0.0, 1.0, 0.0, 0.0], dtype=torch.float64, device=device)  # i
    b = torch.tensor([[0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0]], dtype=torch.float64, device=device)  # j, i
    # i j = k and i i = -1.
    expected = torch.tensor([[0.0, 0.0, 0.0, 1.0], [-1.0, 0.0, 0.0, 0.0]], dtype=torch.float64, device=device)
    assert torch.equal(quat_multiply(a, b), expected)


@pytest.mark.spec("VG-QUAT-MUL")
def test_quat_multiply_gradcheck(device):
    rng = np.random.default_rng(2)
    gradcheck_fn(quat_multiply, (rng.normal(size=(3, 4)), rng.normal(size=(3, 4))), diff=(0, 1), device=device)


@pytest.mark.parametrize(
    "fn, args, name",
    [
        (quat_to_rotmat, (torch.zeros(3, 3),), "q"),
        (quat_to_rotmat, (np.ones((2, 4)),), "q"),
        (quat_multiply, (torch.ones(2, 4), torch.ones(2, 5)), "b"),
        (quat_multiply, (torch.ones(3), torch.ones(4)), "a"),
    ],
)
def test_bad_input_names_the_argument(fn, args, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        fn(*args)
