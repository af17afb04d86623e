"""velogauss_ref.motion.rotscale: VG-ROTSCALE, rotation and log-scale rates of a Gaussian in
an affine velocity field."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import affine_matrix, flat_outputs
from velogauss_ref.motion.rotscale import rotscale_rates
from velogauss_ref.quaternion import quat_to_rotmat

# Sums of a few O(1) float64 products.
TOL = 1e-14

seeds = st.integers(0, 2**32 - 1)
# Any norm, but |q|^2 >= 0.01: far from the zero-quaternion threshold.
quats = hnp.arrays(np.float64, (5, 4), elements=st.floats(-2, 2)).filter(
    lambda q: np.all(np.sum(q * q, axis=1) >= 0.01)
)
coeffs = hnp.arrays(np.float64, (5, 12), elements=st.floats(-3, 3))


def _rates(q, w):
    q_dot, log_s_dot = rotscale_rates(np.asarray(q, float)[None], np.asarray(w, float)[None])
    return q_dot[0], log_s_dot[0]


@pytest.mark.spec("VG-ROTSCALE")
def test_pure_spin_turns_q_and_keeps_scales():
    w = np.zeros(12)
    w[3:6] = [0.2, -0.5, 1.5]
    q_dot, log_s_dot = _rates([1.0, 0, 0, 0], w)
    # q_dot = 1/2 (0, omega) (x) (1, 0, 0, 0) = (0, omega / 2).
    np.testing.assert_allclose(q_dot, [0, 0.1, -0.25, 0.75], rtol=0, atol=TOL)
    np.testing.assert_allclose(log_s_dot, 0.0, rtol=0, atol=TOL)


@pytest.mark.spec("VG-ROTSCALE")
def test_stretch_and_shear_along_the_principal_axes():
    w = np.zeros(12)
    w[6:9] = [0.3, -0.2, 0.7]  # stretch along the world axes
    np.testing.assert_allclose(_rates([1.0, 0, 0, 0], w)[1], [0.3, -0.2, 0.7], rtol=0, atol=TOL)
    # Turned 90 degrees about z, the Gaussian's first axis lies along world y, its second along -x.
    c = math.sqrt(0.5)
    np.testing.assert_allclose(_rates([c, 0, 0, c], w)[1], [-0.2, 0.3, 0.7], rtol=0, atol=TOL)
    w = np.zeros(12)
    w[9] = 0.4  # shear dv_x/dy = dv_y/dx = 0.4: nothing along the world axes, +-0.4 along the diagonals
    np.testing.assert_allclose(_rates([1.0, 0, 0, 0], w)[1], 0.0, rtol=0, atol=TOL)
    s, t = math.cos(math.pi / 8), math.sin(math.pi / 8)  # 45 degrees about z
    np.testing.assert_allclose(_rates([s, 0, 0, t], w)[1], [0.4, -0.4, 0.0], rtol=0, atol=TOL)


@pytest.mark.spec("VG-ROTSCALE")
@given(quats, coeffs)
def test_rates_are_the_spin_product_and_the_axial_strain(q, w):
    q_dot, log_s_dot = rotscale_rates(q, w)
    R = quat_to_rotmat(q)
    for n in range(len(q)):
        A = affine_matrix(w[n])
        D = 0.5 * (A + A.T)
        # Axis k of the Gaussian is column k of R; its log-scale rate is the strain along it.
        np.testing.assert_allclose(log_s_dot[n], [R[n][:, k] @ D @ R[n][:, k] for k in range(3)], rtol=0,
                                   atol=1e-13)
        # 1/2 (0, omega) (x) q, written out: (-omega . v / 2, (q_w omega + omega x v) / 2) for q = (q_w, v).
        omega, qw, v = w[n, 3:6], q[n, 0], q[n, 1:]
        np.testing.assert_allclose(q_dot[n], 0.5 * np.concatenate([[-omega @ v], qw * omega + np.cross(omega, v)]),
                                   rtol=0, atol=1e-13)


@pytest.mark.spec("VG-ROTSCALE")
@given(quats, coeffs, st.sampled_from([-3.0, -1.0, 0.5, 7.0]))
def test_q_need_not_be_unit(q, w, c):
    # q_dot is linear in q; the frame, hence the scale rate, ignores the norm and the sign.
    q_dot, log_s_dot = rotscale_rates(q, w)
    q_dot_c, log_s_dot_c = rotscale_rates(c * q, w)
    np.testing.assert_allclose(q_dot_c, c * q_dot, rtol=0, atol=1e-13 * abs(c))
    np.testing.assert_allclose(log_s_dot_c, log_s_dot, rtol=0, atol=1e-13)


@pytest.mark.spec("VG-ROTSCALE")
@given(quats, coeffs, seeds)
def test_rotscale_rates_gradient(q, w, seed):
    check_grads_fd(flat_outputs(rotscale_rates), (q, w), (0, 1), np.random.default_rng(seed))


@pytest.mark.parametrize(
    "q, w, name",
    [
        (np.zeros((3, 3)), np.zeros((3, 12)), "q"),
        (np.full((3, 4), np.nan), np.zeros((3, 12)), "q"),
        (np.ones((3, 4)), np.zeros((2, 12)), "w"),
        (np.ones((1, 4)), np.full((1, 12), np.inf), "w"),
    ],
)
def test_bad_input_names_the_argument(q, w, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        rotscale_rates(q, w)
