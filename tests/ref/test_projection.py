"""velogauss_ref.projection: VG-PROJ, EWA projection, conic, extent and culling."""

import autograd.numpy as anp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.cameras import in_view, intrinsics, rigid_viewmat, to_world
from tests.ref.gradcheck import check_grads_fd
from velogauss_core.constants import EPS2D, FAR_PLANE, FRUSTUM_GUARD, GAUSSIAN_EXTENT_SIGMA, NEAR_PLANE
from velogauss_ref.covariance import covariance_3d
from velogauss_ref.projection import project_gaussians

# Pixel-scale values (up to ~1e2) through a handful of float64 roundings.
TOL = 1e-10
WIDTH, HEIGHT = 32, 24


def project_isotropic(p_cam, s, K, width=WIDTH, height=HEIGHT):
    """Project Gaussians given in camera space (viewmat = I) with isotropic std s."""
    n = len(p_cam)
    Sigma = np.broadcast_to(s**2 * np.eye(3), (n, 3, 3))
    return project_gaussians(np.asarray(p_cam, float), Sigma, np.eye(4), K, width, height)


cameras = st.builds(
    lambda rotvec, t, f, c: (rigid_viewmat(rotvec, t), intrinsics(f[0], f[1], c[0] * WIDTH, c[1] * HEIGHT)),
    hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)),
    hnp.arrays(np.float64, 3, elements=st.floats(-2.0, 2.0)),
    hnp.arrays(np.float64, 2, elements=st.floats(20.0, 60.0)),
    hnp.arrays(np.float64, 2, elements=st.floats(0.3, 0.7)),
)


@st.composite
def scenes_in_view(draw, n=4):
    """A camera and n Gaussians whose centres project inside the image at depth 1..5.

    Inside the image, x/z is at least FRUSTUM_GUARD tan(fov/2) away from the Jacobian
    clamp, and the Gaussians are far from the near/far planes: no threshold is near.
    """
    viewmat, K = draw(cameras)
    frac = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(0.05, 0.95)))
    z = draw(hnp.arrays(np.float64, n, elements=st.floats(1.0, 5.0)))
    uv = frac * [WIDTH, HEIGHT]
    p = in_view(uv, z, K)
    q = draw(hnp.arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0)).filter(
        lambda q: np.all(np.sum(q * q, axis=-1) >= 0.01)))
    s = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.01, 0.3)))
    return to_world(p, viewmat), covariance_3d(q, s), viewmat, K, uv, z


@pytest.mark.spec("VG-PROJ")
@given(cameras, st.floats(0.5, 20.0))
def test_point_on_optical_axis_lands_on_principal_point(camera, d):
    viewmat, K = camera
    # Camera centre -W^T t plus d along the camera's +z axis (third row of W) in world.
    centre = -viewmat[:3, :3].T @ viewmat[:3, 3]
    mu = centre + d * viewmat[2, :3]
    proj = project_gaussians(mu[None], 0.01 * np.eye(3)[None], viewmat, K, WIDTH, HEIGHT)
    np.testing.assert_allclose(proj["mean2d"][0], K[:2, 2], atol=TOL)
    np.testing.assert_allclose(proj["depth"][0], d, rtol=TOL)
    assert proj["valid"][0]


@pytest.mark.spec("VG-PROJ")
@given(scenes_in_view())
def test_means_follow_the_pinhole_model(scene):
    means, Sigma, viewmat, K, uv, z = scene
    proj = project_gaussians(means, Sigma, viewmat, K, WIDTH, HEIGHT)
    np.testing.assert_allclose(proj["mean2d"], uv, atol=TOL)
    np.testing.assert_allclose(proj["depth"], z, rtol=TOL)
    assert proj["valid"].dtype == bool and proj["valid"].all()
    assert np.issubdtype(proj["radius"].dtype, np.integer)


@pytest.mark.spec("VG-PROJ")
@given(scenes_in_view())
def test_conic_is_the_inverse_of_cov2d(scene):
    means, Sigma, viewmat, K, _, _ = scene
    proj = project_gaussians(means, Sigma, viewmat, K, WIDTH, HEIGHT)
    a, b, c = proj["conic"].T
    conic = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
    np.testing.assert_allclose(conic @ proj["cov2d"], np.broadcast_to(np.eye(2), (4, 2, 2)), atol=1e-9)
    # An off-diagonal entry that is zero up to rounding is compared at the scale of cov2d.
    np.testing.assert_allclose(proj["cov2d"], np.swapaxes(proj["cov2d"], -1, -2), rtol=TOL,
                               atol=TOL * np.abs(proj["cov2d"]).max())


@pytest.mark.spec("VG-PROJ")
def test_isotropic_gaussian_on_axis_has_analytic_cov2d_and_radius():
    fx, fy, z, s = 40.0, 30.0, 2.0, 0.1
    proj = project_isotropic([[0.0, 0.0, z]], s, intrinsics(fx, fy, 16.0, 12.0))
    A, B = (fx * s / z) ** 2 + EPS2D, (fy * s / z) ** 2 + EPS2D  # 4.3, 2.55
    np.testing.assert_allclose(proj["cov2d"][0], np.diag([A, B]), atol=TOL)
    np.testing.assert_allclose(proj["conic"][0], [1 / A, 0.0, 1 / B], atol=TOL)
    # |A - B| / 2 exceeds sqrt(EIGEN_DISCRIMINANT_FLOOR) = 0.1, so lambda_max = A.
    assert proj["radius"][0] == np.ceil(GAUSSIAN_EXTENT_SIGMA * np.sqrt(A))


@pytest.mark.spec("VG-PROJ")
def test_discriminant_floor_widens_an_isotropic_splat():
    # Both eigenvalues A = 0.65 + EPS2D = 0.95: the discriminant is floored at 0.01, so
    # lambda_max = A + 0.1 = 1.05 and the radius is ceil(3 * 1.025) = 4, where the true
    # eigenvalue would give ceil(3 * 0.975) = 3.
    f, z = 40.0, 2.0
    s = np.sqrt(0.65) * z / f
    proj = project_isotropic([[0.0, 0.0, z]], s, intrinsics(f, f, 16.0, 12.0))
    np.testing.assert_allclose(proj["cov2d"][0], 0.95 * np.eye(2), atol=TOL)
    assert proj["radius"][0] == 4


@pytest.mark.spec("VG-PROJ")
def test_tiny_gaussian_is_dilated_to_eps2d():
    proj = project_isotropic([[0.1, -0.2, 3.0]], 1e-7, intrinsics(40.0, 40.0, 16.0, 12.0))
    # (f s / z)^2 ~ 2e-12 px^2: what is left is the dilation EPS2D I.
    np.testing.assert_allclose(proj["cov2d"][0], EPS2D * np.eye(2), atol=1e-10)
    assert proj["radius"][0] == np.ceil(GAUSSIAN_EXTENT_SIGMA * np.sqrt(EPS2D + 0.1))


@pytest.mark.spec("VG-PROJ")
def test_jacobian_is_clamped_outside_the_frustum():
    fx, fy, cx, cy, z, s = 40.0, 30.0, 10.0, 8.0, 2.0, 0.5  # off-centre principal point
    lim_x_pos = (WIDTH - cx) / fx + FRUSTUM_GUARD * 0.5 * WIDTH / fx  # 0.67
    lim_y_neg = cy / fy + FRUSTUM_GUARD * 0.5 * HEIGHT / fy  # 0.39
    # Beyond the right limit (x/z = 3, 9) and beyond the top limit (y/z = -1, -5): the
    # Jacobian is taken at the clamped point, whatever the distance beyond.
    ratios = [(3.0, 0.0), (9.0, 0.0), (0.0, -1.0), (0.0, -5.0)]
    proj = project_isotropic([[rx * z, ry * z, z] for rx, ry in ratios], s, intrinsics(fx, fy, cx, cy))
    for k, (tx, ty) in enumerate([(z * lim_x_pos, 0.0)] * 2 + [(0.0, -z * lim_y_neg)] * 2):
        J = np.array([[fx / z, 0.0, -fx * tx / z**2], [0.0, fy / z, -fy * ty / z**2]])
        np.testing.assert_allclose(proj["cov2d"][k], s**2 * J @ J.T + EPS2D * np.eye(2), atol=TOL)
    # The mean itself is not clamped.
    np.testing.assert_allclose(proj["mean2d"], [[fx * rx + cx, fy * ry + cy] for rx, ry in ratios], atol=TOL)


@pytest.mark.spec("VG-PROJ")
def test_indefinite_covariance_is_culled_with_a_finite_conic():
    # Sigma = diag(1, -1, 0) (not a covariance) gives cov2d = diag(100.3, -99.7): det < 0.
    proj = project_gaussians(np.array([[0.0, 0.0, 2.0]]), np.diag([1.0, -1.0, 0.0])[None], np.eye(4),
                             intrinsics(20.0, 20.0, 16.0, 12.0), WIDTH, HEIGHT)
    np.testing.assert_allclose(proj["cov2d"][0], np.diag([100.3, -99.7]), atol=TOL)
    assert not proj["valid"][0]
    assert np.all(np.isfinite(proj["conic"]))


@pytest.mark.spec("VG-PROJ")
def test_near_and_far_culling_boundaries():
    K = intrinsics(40.0, 40.0, 16.0, 12.0)
    depths = [NEAR_PLANE * 0.999, NEAR_PLANE, 1.0, FAR_PLANE, FAR_PLANE * 1.001, 0.0, -1.0]
    proj = project_isotropic([[0.0, 0.0, d] for d in depths], 1e-3, K)
    np.testing.assert_array_equal(proj["valid"], [False, True, True, True, False, False, False])
    for key in ("mean2d", "depth", "cov2d", "conic"):
        assert np.all(np.isfinite(proj[key])), key


@pytest.mark.spec("VG-PROJ")
def test_off_screen_culling_uses_the_box():
    fx, z = 40.0, 2.0
    K = intrinsics(fx, fx, 16.0, 12.0)
    r = project_isotropic([[0.0, 0.0, z]], 0.1, K)["radius"][0]  # radius of this splat anywhere on the z plane
    # Box right edge u + r at -0.5 (culled) and at +0.5 (kept); same on the far side.
    us = [-r - 0.5, -r + 0.5, WIDTH + r + 0.5, WIDTH + r - 0.5]
    proj = project_isotropic([[(u - 16.0) * z / fx, 0.0, z] for u in us], 0.1, K)
    np.testing.assert_array_equal(proj["radius"], r)
    np.testing.assert_array_equal(proj["valid"], [False, True, False, True])


@pytest.mark.spec("VG-PROJ")
@given(scenes_in_view(), st.integers(0, 2**32 - 1))
def test_project_gaussians_gradient(scene, seed):
    means, Sigma, viewmat, K, _, _ = scene
    rng = np.random.default_rng(seed)

    def float_outputs(means, Sigma):
        proj = project_gaussians(means, Sigma, viewmat, K, WIDTH, HEIGHT)
        parts = [proj["mean2d"], proj["depth"], proj["cov2d"], proj["conic"]]
        return anp.concatenate([anp.ravel(x) for x in parts])

    check_grads_fd(float_outputs, (means, Sigma), (0, 1), rng)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"means": np.zeros((2, 2))}, "means"),
        ({"means": np.array([[0.0, np.nan, 1.0]] * 2)}, "means"),
        ({"Sigma": np.zeros((3, 3, 3))}, "Sigma"),
        ({"Sigma": np.full((2, 3, 3), np.inf)}, "Sigma"),
        ({"viewmat": np.eye(3)}, "viewmat"),
        ({"K": np.full((3, 3), np.nan)}, "K"),
        ({"width": 0}, "width"),
        ({"width": 8.0}, "width"),
        ({"height": True}, "height"),
        ({"height": -3}, "height"),
    ],
)
def test_bad_input_names_the_argument(kwargs, name):
    args = dict(means=np.ones((2, 3)), Sigma=np.broadcast_to(np.eye(3), (2, 3, 3)), viewmat=np.eye(4),
                K=intrinsics(10.0, 10.0, 4.0, 4.0), width=8, height=8)
    args.update(kwargs)
    with pytest.raises(ValueError, match=f"^{name}:"):
        project_gaussians(**args)
