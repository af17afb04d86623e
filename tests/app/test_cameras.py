"""Camera conventions (spec/conventions.md, "Cameras", "Pixels"): velogauss/data/cameras.py."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from velogauss.data.cameras import (
    Camera,
    c2w_opengl_from_viewmat,
    intrinsics_from_focal,
    intrinsics_from_fov,
    look_at,
    viewmat_from_c2w_opengl,
)

# Exact arithmetic on small integers and one 4x4 inverse: agreement to float64 rounding.
TIGHT = 1e-12


def _blender_camera_on_minus_y():
    """A Blender camera at (0, -4, 0) looking along +y with +z up, written by hand in OpenGL axes:
    camera x = world +x (right), camera y = world +z (up), camera z = world -y (backward)."""
    c2w = np.eye(4)
    c2w[:3, 0] = [1.0, 0.0, 0.0]
    c2w[:3, 1] = [0.0, 0.0, 1.0]
    c2w[:3, 2] = [0.0, -1.0, 0.0]
    c2w[:3, 3] = [0.0, -4.0, 0.0]
    return c2w


def test_c2w_opengl_to_viewmat_centre_and_forward():
    cam = Camera.from_c2w_opengl(_blender_camera_on_minus_y(), intrinsics_from_focal(50.0, 50.0, 32.0, 24.0), 64, 48)
    np.testing.assert_allclose(cam.centre, [0.0, -4.0, 0.0], atol=TIGHT)
    # OpenCV +z is the looking direction: world +y for this camera.
    np.testing.assert_allclose(cam.forward, [0.0, 1.0, 0.0], atol=TIGHT)
    np.testing.assert_allclose(cam.viewmat[:3, :3] @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=TIGHT)


def test_point_in_front_projects_with_positive_depth_to_the_right_pixel():
    cam = Camera.from_c2w_opengl(_blender_camera_on_minus_y(), intrinsics_from_focal(50.0, 50.0, 32.0, 24.0), 64, 48)
    points = np.array([
        [0.0, 0.0, 0.0],  # on the optical axis, 4 units ahead
        [0.5, 0.0, 0.0],  # to the right: u grows
        [0.0, 0.0, 0.5],  # up in the world: v shrinks (OpenCV +y is down)
        [0.0, -6.0, 0.0],  # behind the camera
    ])
    uv, depth = cam.project(points)
    np.testing.assert_allclose(depth, [4.0, 4.0, 4.0, -2.0], atol=TIGHT)
    np.testing.assert_allclose(uv[:3], [[32.0, 24.0], [32.0 + 50.0 * 0.5 / 4.0, 24.0], [32.0, 24.0 - 50.0 * 0.5 / 4.0]],
                               atol=TIGHT)


def test_viewmat_round_trip(rng):
    for _ in range(5):
        c2w = np.eye(4)
        c2w[:3, :3] = Rotation.random(random_state=rng).as_matrix()
        c2w[:3, 3] = rng.normal(size=3) * 3
        viewmat = viewmat_from_c2w_opengl(c2w)
        np.testing.assert_allclose(viewmat @ c2w @ np.diag([1.0, -1.0, -1.0, 1.0]), np.eye(4), atol=TIGHT)
        np.testing.assert_allclose(c2w_opengl_from_viewmat(viewmat), c2w, atol=TIGHT)


def test_intrinsics_from_fov_matches_the_formula():
    # tan(0.5 * fov) = 0.5 -> fx = 0.5 * 100 / 0.5 = 100.
    K = intrinsics_from_fov(2.0 * np.arctan(0.5), 100, 60)
    np.testing.assert_allclose(K, [[100.0, 0.0, 50.0], [0.0, 100.0, 30.0], [0.0, 0.0, 1.0]], atol=TIGHT)


def test_pixel_rays_pass_through_pixel_centres():
    cam = Camera(look_at([3.0, -2.0, 1.5], [0.1, 0.2, -0.3]), intrinsics_from_focal(9.0, 11.0, 3.7, 2.9), 6, 5)
    origins, dirs = cam.pixel_rays()
    assert dirs.shape == (5, 6, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=TIGHT)
    np.testing.assert_allclose(origins, np.broadcast_to(cam.centre, origins.shape), atol=TIGHT)
    uv, depth = cam.project(origins + 2.5 * dirs)
    ii, jj = np.mgrid[0:5, 0:6]
    np.testing.assert_allclose(uv, np.stack([jj + 0.5, ii + 0.5], axis=-1), atol=1e-9)
    assert np.all(depth > 0)


def test_supersampled_rays_average_to_the_pixel_centre():
    cam = Camera(look_at([0.0, -4.0, 0.0], [0.0, 0.0, 0.0]), intrinsics_from_focal(8.0, 8.0, 2.0, 2.0), 4, 4)
    origins, dirs = cam.pixel_rays(supersample=3)
    uv, _ = cam.project(origins + dirs)
    # The 3x3 sub-pixel samples of pixel (i, j) sit at (j + (b + 0.5)/3, i + (a + 0.5)/3).
    np.testing.assert_allclose(uv[:3, :3].reshape(-1, 2).mean(axis=0), [0.5, 0.5], atol=1e-9)
    np.testing.assert_allclose(uv[0, 0], [1.0 / 6.0, 1.0 / 6.0], atol=1e-9)


def test_optical_axis_lands_between_the_middle_columns():
    cam = Camera(look_at([0.0, -4.0, 0.0], [0.0, 0.0, 0.0]), intrinsics_from_fov(0.7, 8, 8), 8, 8)
    uv, _ = cam.project(np.zeros((1, 3)))
    np.testing.assert_allclose(uv[0], [4.0, 4.0], atol=TIGHT)
    _, dirs = cam.pixel_rays()
    # Rays of columns 3 and 4 are mirror images about the optical axis.
    right = cam.viewmat[0, :3]
    np.testing.assert_allclose(dirs[:, 3] @ right, -(dirs[:, 4] @ right), atol=TIGHT)


def test_look_at_points_the_camera_at_the_target_with_world_up_up():
    eye, target = np.array([2.0, -3.0, 2.5]), np.array([0.3, 0.1, -0.2])
    cam = Camera(look_at(eye, target), intrinsics_from_focal(20.0, 20.0, 16.0, 12.0), 32, 24)
    np.testing.assert_allclose(cam.centre, eye, atol=TIGHT)
    np.testing.assert_allclose(cam.forward, (target - eye) / np.linalg.norm(target - eye), atol=TIGHT)
    uv, _ = cam.project(np.stack([target, target + [0.0, 0.0, 0.3]]))
    np.testing.assert_allclose(uv[0], [16.0, 12.0], atol=1e-9)
    assert uv[1, 1] < uv[0, 1]  # world up is image up
    assert abs(uv[1, 0] - uv[0, 0]) < 1e-9  # no roll: world up stays vertical in the image


def test_downsampled_camera_halves_intrinsics_and_pixel_coordinates():
    cam = Camera(look_at([3.0, -2.0, 1.5], [0.0, 0.0, 0.0]), intrinsics_from_focal(40.0, 42.0, 16.5, 12.25), 33, 25)
    half = cam.downsampled(2)
    assert (half.width, half.height) == (16, 12)
    np.testing.assert_allclose(half.K, [[20.0, 0.0, 8.25], [0.0, 21.0, 6.125], [0.0, 0.0, 1.0]], atol=TIGHT)
    p = np.array([[0.2, -0.1, 0.3]])
    np.testing.assert_allclose(half.project(p)[0], cam.project(p)[0] / 2.0, atol=1e-9)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda m: m.__setitem__((0, 0), np.nan), "non-finite"),
        (lambda m: m.__setitem__((slice(0, 3), slice(0, 3)), 0.0), "not a rotation"),
        (lambda m: m.__setitem__((slice(0, 3), slice(0, 3)), 2.0 * m[:3, :3]), "not a rotation"),
        (lambda m: m.__setitem__((3, 2), 1.0), "bottom row"),
    ],
    ids=["nan", "singular", "scaled", "projective"],
)
def test_bad_pose_raises_naming_the_argument(mutate, message):
    c2w = _blender_camera_on_minus_y()
    mutate(c2w)
    with pytest.raises(ValueError, match=rf"^c2w_gl: .*{message}"):
        viewmat_from_c2w_opengl(c2w)


def test_reflection_is_accepted_as_orthonormal():
    # det = -1 passes (the brief asks for |det| ~ 1); it stays invertible and round-trips.
    c2w = _blender_camera_on_minus_y() @ np.diag([-1.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(c2w_opengl_from_viewmat(viewmat_from_c2w_opengl(c2w)), c2w, atol=TIGHT)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: intrinsics_from_fov(0.0, 8, 8), "camera_angle_x"),
        (lambda: intrinsics_from_fov(np.pi, 8, 8), "camera_angle_x"),
        (lambda: intrinsics_from_focal(-1.0, 1.0, 0.0, 0.0), "fl_x"),
        (lambda: intrinsics_from_focal(1.0, 1.0, np.inf, 0.0), "cx"),
        (lambda: Camera(np.eye(4), np.eye(3), 0, 4), "width"),
        (lambda: Camera(np.eye(4), np.zeros((3, 3)), 4, 4), "K"),
        (lambda: look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0]), "up"),
        (lambda: look_at([1.0, 0.0, 0.0], [1.0, 0.0, 0.0]), "target"),
        (lambda: Camera(np.eye(4), np.eye(3), 4, 4).pixel_rays(0), "supersample"),
    ],
)
def test_bad_arguments_raise_naming_them(call, name):
    with pytest.raises(ValueError, match=rf"^{name}: "):
        call()
