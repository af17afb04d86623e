"""The seen / unseen split of the velocity error (velogauss.diagnose.visibility)."""

import numpy as np
import pytest
import torch

from velogauss.data.cameras import Camera, intrinsics_from_fov, look_at
from velogauss.data.dnerf import Frame
from velogauss.diagnose.visibility import seen_points, split_velocity_errors
from velogauss.evaluate import moving_surface_points
from velogauss.scenes.bodies import Body, Texture
from velogauss.scenes.trajectories import RigidMotion, StaticMotion
from velogauss.scenes.scene import AnalyticScene

PLAIN = Texture("checker", ((1, 0, 0), (0, 0, 1)))
# A camera at height H above the unit ball's centre sees exactly the points with z > 1 / H
# (p · c > r², the cap inside the tangent cone); the test keeps this far from the boundary.
H = 4.0
BAND = 0.02


def _frame(eye, time=0.0, fov=1.2, size=64):
    camera = Camera(look_at(eye, (eye[0], eye[1], 0.0), up=(0.0, 1.0, 0.0)), intrinsics_from_fov(fov, size, size),
                    size, size)
    return Frame(np.zeros((size, size, 3), np.uint8), time, camera, "synthetic")


def _ball(motion=None, centre=(0.0, 0.0, 0.0)):
    return Body("ball", "ellipsoid", centre, (1.0, 1.0, 1.0), np.eye(3), PLAIN,
                RigidMotion(centre=centre) if motion is None else motion)


def _sphere_points(n=400, seed=0):
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def test_a_camera_above_sees_the_cap_inside_its_tangent_cone():
    scene = AnalyticScene("one", [_ball()], effects=["translation"], incompressible=True)
    x0 = _sphere_points()
    far = np.abs(x0[:, 2] - 1.0 / H) > BAND
    seen = seen_points(scene, [_frame((0.0, 0.0, H))], x0)
    np.testing.assert_array_equal(seen[far], x0[far, 2] > 1.0 / H)


def test_an_occluder_between_the_camera_and_the_ball_hides_what_it_covers():
    # A small ball of radius R at height 2 hides the points whose ray from the camera passes
    # within R of its centre: |(o − c) × u| < R, u the unit direction from the camera c.
    R = 0.2
    marble = Body("marble", "ellipsoid", (0.0, 0.0, 2.0), (R, R, R), np.eye(3), PLAIN, StaticMotion())
    scene = AnalyticScene("two", [_ball(), marble], effects=["translation"], incompressible=True)
    x0 = _sphere_points(2000)
    seen = seen_points(scene, [_frame((0.0, 0.0, H))], x0)
    u = x0 - [0.0, 0.0, H]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    miss = np.linalg.norm(np.cross([0.0, 0.0, 2.0 - H], u), axis=1)
    clear = (np.abs(miss - R) > BAND) & (x0[:, 2] > 1.0 / H + BAND)
    hidden = miss < R
    assert (clear & hidden).sum() > 5 and (clear & ~hidden).sum() > 100
    np.testing.assert_array_equal(seen[clear], ~hidden[clear])


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_points_outside_the_image_are_unseen_and_frames_look_at_their_own_time(side):
    # The ball starts 3 units to one side of a narrow camera and crosses under it at t = 0.5.
    start = (3.0 * side, 0.0, 0.0)
    scene = AnalyticScene("cross", [_ball(RigidMotion(centre=start, velocity=(-6.0 * side, 0.0, 0.0)), centre=start)],
                          effects=["translation"], incompressible=True)
    x0 = _sphere_points() + start
    top = x0[:, 2] > 0.9
    assert not seen_points(scene, [_frame((0.0, 0.0, H), time=0.0, fov=0.5)], x0).any()
    assert seen_points(scene, [_frame((0.0, 0.0, H), time=0.5, fov=0.5)], x0)[top].all()


class _TopOnly:
    """A stand-in model whose particle velocity is the truth on the ball's upper cap (z0 > 0.5)
    and zero below it."""

    has_velocity = True

    def __init__(self, scene):
        self.scene = scene

    def particle_velocity(self, x0, x, t):
        truth = self.scene.velocity(x.numpy().astype(np.float64), t, margin=np.inf)
        return torch.as_tensor(np.where(x0.numpy()[:, 2:] > 0.5, truth, 0.0))

    def velocity_at(self, x, t):
        return torch.zeros_like(x)


def test_split_errors_put_the_wrong_velocity_where_no_camera_looks():
    scene = AnalyticScene("one", [_ball(RigidMotion(centre=(0.0, 0.0, 0.0), velocity=(0.5, 0.0, 0.0),
                                                    omega=(0.0, 0.0, 1.0)))],
                          effects=["translation", "rotation"], incompressible=True)
    # Seen: z0 > 1/H = 0.25 over the frames up to t = 0.75 (the ball moves 0.375 sideways;
    # the camera follows). The model is right above z0 = 0.5 only, so the seen part's error
    # is that of the band 0.25 < z0 < 0.5 and the unseen part's is exactly 1.
    frames = [_frame((0.5 * t, 0.0, H), time=t) for t in (0.0, 0.375, 0.75)]
    rows = {(r["body"], r["part"]): r for r in split_velocity_errors(_TopOnly(scene), scene, frames, 0.75)}
    assert set(rows) == {("ball", "seen"), ("ball", "unseen"), ("all", "seen"), ("all", "unseen")}
    assert rows["ball", "unseen"]["observed"] == pytest.approx(1.0)
    assert rows["ball", "unseen"]["future"] == pytest.approx(1.0)
    assert 0.0 < rows["ball", "seen"]["observed"] < 1.0
    assert rows["all", "seen"] == {**rows["ball", "seen"], "body": "all"}
    assert rows["ball", "seen"]["points"] + rows["ball", "unseen"]["points"] == len(moving_surface_points(scene))
