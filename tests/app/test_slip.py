"""How far a body's Gaussians turn and slip against the body (velogauss.diagnose.slip), on
Gaussians moved by hand along known rotations."""

import numpy as np
import pytest

from velogauss.diagnose.slip import angle, best_rotation, body_gaussians, slip_rows
from velogauss.scenes.bodies import Body, Texture
from velogauss.scenes.scene import AnalyticScene
from velogauss.scenes.trajectories import RigidMotion, StaticMotion
from velogauss_core.constants import ALPHA_MIN

PLAIN = Texture("checker", ((1, 0, 0), (0, 0, 1)))
SPIN = 2.0  # rad per unit time about z, through the body's centre
CENTRE = np.array([0.5, -0.25, 0.0])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _scene():
    """A box spinning in place about z and a still box far from it."""
    spinning = Body("spinner", "box", CENTRE, (0.3, 0.2, 0.1), np.eye(3), PLAIN,
                    RigidMotion(centre=CENTRE, omega=(0.0, 0.0, SPIN)))
    still = Body("still", "box", (5.0, 5.0, 5.0), (0.3, 0.3, 0.3), np.eye(3), PLAIN, StaticMotion())
    return AnalyticScene("slip", [spinning, still], effects=["rotation", "static"], incompressible=True)


def _points(n=200, seed=0):
    """n points inside the spinning box (half sizes 0.3, 0.2, 0.1) and 3 inside the still one."""
    rng = np.random.default_rng(seed)
    inside = CENTRE + rng.uniform(-1, 1, size=(n, 3)) * np.array([0.29, 0.19, 0.09])
    return np.concatenate([inside, np.array([[5.0, 5.0, 5.0], [5.1, 5.0, 5.0], [5.0, 5.1, 5.0]])])


def _turned(means0, rate):
    """Positions at t of points turned about z through CENTRE at `rate` rad per unit time."""
    return lambda t: (means0 - CENTRE) @ _rz(rate * t).T + CENTRE


def test_best_rotation_recovers_a_turn_and_a_shift():
    start = np.random.default_rng(1).normal(size=(20, 3))
    rotation = _rz(np.radians(30.0)) @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    end = start @ rotation.T + np.array([1.0, 2.0, 3.0])
    r, b = best_rotation(start, end)
    np.testing.assert_allclose(r, rotation, atol=1e-12)
    np.testing.assert_allclose(b, [1.0, 2.0, 3.0], atol=1e-12)
    assert angle(_rz(np.radians(30.0))) == pytest.approx(30.0)
    assert angle(np.eye(3)) == 0.0


def test_the_moving_body_keeps_its_opaque_gaussians_and_the_still_one_is_left_out():
    means0 = _points()
    opacities = np.full(len(means0), 0.9)
    opacities[:10] = ALPHA_MIN / 2  # too faint to count
    groups = body_gaussians(_scene(), means0, opacities)
    assert list(groups) == [0]
    np.testing.assert_array_equal(groups[0], np.arange(10, 200))


def test_gaussians_that_follow_the_material_turn_with_the_body_and_do_not_slip():
    means0 = _points()
    groups = body_gaussians(_scene(), means0, np.ones(len(means0)))
    rows = slip_rows(_scene(), means0, _turned(means0, SPIN), groups, times=(0.25, 0.5))
    assert [(r["body"], r["time"], r["points"]) for r in rows] == [("spinner", 0.25, 200), ("spinner", 0.5, 200)]
    for row in rows:
        assert row["true_turn"] == pytest.approx(np.degrees(SPIN * row["time"]))
        assert row["model_turn"] == pytest.approx(row["true_turn"])
        assert row["turn_error"] == pytest.approx(0.0, abs=1e-5)
        assert row["slip"] == pytest.approx(0.0, abs=1e-12)
        assert row["nonrigid"] == pytest.approx(0.0, abs=1e-12)


def test_gaussians_that_turn_at_half_the_rate_slip_rigidly():
    """Turned by a instead of 2a about the same axis, each point is 2 r sin(a / 2) from its material
    point, which is 2 r sin(a) from its start: the slip is sin(a / 2) / sin(a) at every radius."""
    means0 = _points()
    groups = body_gaussians(_scene(), means0, np.ones(len(means0)))
    (row,) = slip_rows(_scene(), means0, _turned(means0, SPIN / 2), groups, times=(0.5,))
    a = SPIN / 2 * 0.5
    assert row["true_turn"] == pytest.approx(np.degrees(2 * a))
    assert row["model_turn"] == pytest.approx(np.degrees(a))
    assert row["turn_error"] == pytest.approx(np.degrees(a))
    assert row["slip"] == pytest.approx(np.sin(a / 2) / np.sin(a))
    assert row["nonrigid"] == pytest.approx(0.0, abs=1e-12)


def test_gaussians_that_drift_apart_are_not_rigid():
    """Every Gaussian pushed out from the axis by 10 % of its distance while the body only turns."""
    means0 = _points()
    groups = body_gaussians(_scene(), means0, np.ones(len(means0)))
    turned = _turned(means0, SPIN)
    spread = lambda t: CENTRE + (turned(t) - CENTRE) * np.array([1.1, 1.1, 1.0])  # noqa: E731
    (row,) = slip_rows(_scene(), means0, spread, groups, times=(0.5,))
    assert row["turn_error"] < 1.0
    assert row["nonrigid"] > 0.01
    assert row["slip"] > row["nonrigid"]
