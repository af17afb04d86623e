"""velogauss_ref.sh: VG-SH, view-dependent colour from real spherical harmonics."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.special import sph_harm_y

from tests.ref.cameras import rigid_viewmat
from tests.ref.gradcheck import check_grads_fd
from velogauss_core.constants import VIEW_DIRECTION_MIN
from velogauss_ref.sh import C0, C1, camera_centre, sh_basis, sh_to_color, viewing_directions

# Sums of at most 16 O(1) float64 products.
TOL = 1e-12

directions = hnp.arrays(np.float64, (5, 3), elements=st.floats(-2.0, 2.0)).filter(
    lambda d: np.all(np.linalg.norm(d, axis=-1) >= 0.1)
)


def coefficients(k, bound=1.0):
    return hnp.arrays(np.float64, (5, k, 3), elements=st.floats(-bound, bound))


@pytest.mark.spec("VG-SH")
@given(coefficients(16), directions, directions)
def test_degree_zero_is_c0_times_dc_plus_half_and_view_independent(sh, d1, d2):
    expected = np.maximum(C0 * sh[:, 0] + 0.5, 0.0)
    np.testing.assert_allclose(sh_to_color(sh, d1, 0), expected, atol=TOL)
    np.testing.assert_allclose(sh_to_color(sh, d2, 0), expected, atol=TOL)


@pytest.mark.spec("VG-SH")
def test_degree_one_follows_the_3dgs_sign_convention():
    # 3DGS: band 1 is (-C1 y, C1 z, -C1 x) times coefficients 1, 2, 3.
    sh = np.zeros((3, 4, 3))
    sh[:, 1:4, 0] = 0.2
    dirs = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    np.testing.assert_allclose(sh_to_color(sh, dirs, 1)[:, 0], 0.5 + 0.2 * C1, atol=TOL)
    np.testing.assert_allclose(sh_to_color(sh, -dirs, 1)[:, 0], 0.5 - 0.2 * C1, atol=TOL)


@pytest.mark.spec("VG-SH")
@given(directions)
def test_basis_matches_scipy_spherical_harmonics(dirs):
    # Independent oracle: scipy's complex Y_l^m (Condon-Shortley phase included) made real
    # the way 3DGS's eval_sh is: sqrt(2) Im Y_l^|m| for m < 0, Y_l^0, sqrt(2) Re Y_l^m for
    # m > 0, in the order m = -l..l within band l.
    unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    # arctan2, not arccos(z): arccos loses half the digits of theta next to the poles.
    theta = np.arctan2(np.hypot(unit[:, 0], unit[:, 1]), unit[:, 2])
    phi = np.arctan2(unit[:, 1], unit[:, 0])
    expected = []
    for band in range(4):
        for m in range(-band, band + 1):
            Y = sph_harm_y(band, abs(m), theta, phi)
            expected.append(np.sqrt(2) * Y.imag if m < 0 else (Y.real if m == 0 else np.sqrt(2) * Y.real))
    np.testing.assert_allclose(sh_basis(unit, 3), np.stack(expected, axis=-1), atol=1e-12)


@pytest.mark.spec("VG-SH")
@given(coefficients(16), directions, st.sampled_from([0, 1, 2, 3]))
def test_colour_is_the_basis_expansion_plus_half(sh, dirs, degree):
    k = (degree + 1) ** 2
    unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    expected = np.maximum(np.einsum("nk,nkc->nc", sh_basis(unit, degree), sh[:, :k]) + 0.5, 0.0)
    np.testing.assert_allclose(sh_to_color(sh, dirs, degree), expected, atol=TOL)


@pytest.mark.spec("VG-SH")
@given(coefficients(16), directions, st.sampled_from([0, 1, 2, 3]), st.floats(0.01, 100.0))
def test_direction_length_and_higher_bands_are_ignored(sh, dirs, degree, c):
    rgb = sh_to_color(sh, dirs, degree)
    np.testing.assert_allclose(sh_to_color(sh, c * dirs, degree), rgb, atol=TOL)
    k = (degree + 1) ** 2
    np.testing.assert_allclose(sh_to_color(sh[:, :k], dirs, degree), rgb, atol=TOL)
    np.testing.assert_allclose(sh_to_color(np.concatenate([sh[:, :k], 7 + sh[:, k:]], 1), dirs, degree), rgb, atol=TOL)


@pytest.mark.spec("VG-SH")
def test_a_direction_shorter_than_the_threshold_is_plus_z():
    # Rounding noise of the camera centre (1e-17) must not pick a colour (VIEW_DIRECTION_MIN).
    sh = np.random.default_rng(0).normal(size=(1, 16, 3)) * 0.2
    tilted = np.array([[1.0, 2.0, -2.0]]) / 3.0
    plus_z = sh_to_color(sh, np.array([[0.0, 0.0, 1.0]]), 3)
    for d in (np.zeros((1, 3)), 3e-17 * tilted, 0.99 * VIEW_DIRECTION_MIN * tilted):
        np.testing.assert_array_equal(sh_to_color(sh, d, 3), plus_z)
    np.testing.assert_allclose(sh_to_color(sh, 1.01 * VIEW_DIRECTION_MIN * tilted, 3), sh_to_color(sh, tilted, 3),
                               atol=TOL)


@pytest.mark.spec("VG-SH")
def test_negative_colour_is_clamped_to_zero():
    sh = np.zeros((1, 1, 3))
    sh[0, 0] = [-10.0, -0.5 / C0, 1.0]
    np.testing.assert_allclose(sh_to_color(sh, np.ones((1, 3)), 0), [[0.0, 0.0, C0 + 0.5]], atol=TOL)


@pytest.mark.spec("VG-SH")
@given(hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)),
       hnp.arrays(np.float64, 3, elements=st.floats(-5.0, 5.0)))
def test_camera_centre_and_viewing_directions(rotvec, centre):
    W = rigid_viewmat(rotvec, np.zeros(3))[:3, :3]
    viewmat = rigid_viewmat(rotvec, -W @ centre)  # a camera at `centre`
    np.testing.assert_allclose(camera_centre(viewmat), centre, atol=1e-12)
    means = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(viewing_directions(means, viewmat), means - centre, atol=1e-12)


@pytest.mark.spec("VG-SH")
@given(coefficients(16, bound=0.3), directions, st.sampled_from([0, 1, 2, 3]), st.integers(0, 2**32 - 1))
def test_sh_to_color_gradient(sh, dirs, degree, seed):
    # Away from the clamp at 0: every channel at least 0.01 above it.
    assume(np.all(sh_to_color(sh, dirs, degree) > 0.01))
    check_grads_fd(lambda sh, dirs: sh_to_color(sh, dirs, degree), (sh, dirs), (0, 1), np.random.default_rng(seed))


@pytest.mark.parametrize(
    "sh, dirs, degree, name",
    [
        (np.zeros((2, 16, 3)), np.ones((2, 3)), 4, "degree"),
        (np.zeros((2, 16, 3)), np.ones((2, 3)), -1, "degree"),
        (np.zeros((2, 16, 3)), np.ones((2, 3)), 1.0, "degree"),
        (np.zeros((2, 16, 3)), np.ones((2, 3)), True, "degree"),
        (np.zeros((2, 8, 3)), np.ones((2, 3)), 2, "sh"),
        (np.zeros((2, 4)), np.ones((2, 3)), 0, "sh"),
        (np.full((2, 4, 3), np.nan), np.ones((2, 3)), 1, "sh"),
        (np.zeros((2, 4, 3)), np.ones((3, 3)), 1, "dirs"),
        (np.zeros((2, 4, 3)), np.array([[1.0, np.inf, 0.0]] * 2), 1, "dirs"),
    ],
)
def test_bad_input_names_the_argument(sh, dirs, degree, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        sh_to_color(sh, dirs, degree)
