"""The random scene family (velogauss/scenes/family.py), its new motions (trajectories.py) and
`velogauss make-scene --random`: determinism, the distribution's coverage and ranges, exact
ground truth through scene.json, bodies in view, and a small scene loaded end to end."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.data import DataError, load_scene
from velogauss.scenes import family, load_ground_truth, make_random_scene
from velogauss.scenes.bodies import body_from_dict
from velogauss.scenes.scene import AnalyticScene
from velogauss.scenes.trajectories import (BounceMotion, OrbitMotion, OscillatingStretchMotion, PendulumMotion,
                                           motion_from_dict)

# Enough draws that each of the 8 kinds, 3 rigs and 3 shapes is expected dozens of times.
N_DRAWS = 200
# A small draw (a 4-camera ring, 16 frames of 64 px, an orbit and a bounce over the ground).
SMALL_SEED = 34
# Central differences: truncation ~h^2 |x'''| and rounding ~1e-16/h, both far below these.
H = 1e-5
FD_TOL, FD_ACC_TOL = 1e-6, 1e-4


@pytest.fixture(scope="module")
def draws():
    return [family.draw_parameters(seed) for seed in range(N_DRAWS)]


def _tiny(seed, out, **options):
    return make_random_scene(seed, out, **{"resolution": 16, "n_frames": 6, "supersample": 1, "n_points": 50,
                                           **options})


# --- determinism ------------------------------------------------------------------------------


def test_the_same_seed_gives_the_same_scene(tmp_path):
    assert family.draw_parameters(5) == family.draw_parameters(5)
    a, b = _tiny(5, tmp_path / "a"), _tiny(5, tmp_path / "b")
    assert (a / "scene.json").read_bytes() == (b / "scene.json").read_bytes()
    first = sorted((a / "train").glob("*.png"))[0]
    assert first.read_bytes() == (b / "train" / first.name).read_bytes()
    assert (a / "points3d.ply").read_bytes() == (b / "points3d.ply").read_bytes()


def test_different_seeds_give_different_scenes(draws):
    bodies = [json.dumps(d["bodies"]) for d in draws[:20]]
    assert len(set(bodies)) == len(bodies)


def test_seed_lists_are_disjoint_and_a_bad_seed_is_refused():
    assert not set(family.TUNING_SEEDS) & set(family.REPORT_SEEDS)
    for seed in (-1, 1.5, True):
        with pytest.raises(ValueError, match="^seed: "):
            family.draw_parameters(seed)


# --- the distribution -------------------------------------------------------------------------


def test_every_kind_rig_shape_and_count_appears(draws):
    assert {k for d in draws for k in d["kinds"]} == set(family.KINDS)
    assert {d["rig"] for d in draws} == set(family.RIGS)
    assert {b["primitive"] for d in draws for b in d["bodies"]} == set(family.SHAPES)
    assert {len(d["kinds"]) for d in draws} == {1, 2, 3}
    assert {d["background"] for d in draws} == {"white", "black"}
    assert {d["ground"] is None for d in draws} == {True, False}


def _in(value, bounds, tol=1e-12):
    return bounds[0] - tol <= value <= bounds[1] + tol


def test_draws_hold_the_documented_ranges(draws):
    for d in draws:
        assert _in(d["resolution"], family.RESOLUTION) and d["resolution"] % family.RESOLUTION_STEP == 0
        assert _in(d["n_frames"], family.N_FRAMES) and _in(d["n_cameras"], family.N_CAMERAS)
        assert len(d["azimuths_deg"]) == len(d["elevations_deg"]) == d["n_cameras"]
        assert _in(d["future_fraction"], family.FUTURE_FRACTION)
        # The window ends at the frame nearest 1 - F: within half a frame step of it.
        assert abs((1.0 - d["max_time"]) - d["future_fraction"]) <= 0.5 / (d["n_frames"] - 1) + 1e-12
        assert _in(d["ambient"], family.AMBIENT) and any(k != "still" for k in d["kinds"])
        assert d["ground"] is not None or "bounce" not in d["kinds"]
        for kind, body in zip(d["kinds"], d["bodies"]):
            assert body["kind"] == kind
            assert all(_in(s, family.HALF_SIZE) for s in body["size"])
            colors = np.array(body["texture"]["colors"])
            assert np.linalg.norm(colors[0] - colors[1]) >= family.MIN_CONTRAST
            _check_motion_ranges(kind, body["motion"])


def _check_motion_ranges(kind, m):
    expected = {"flight": "rigid", "spin": "rigid", "orbit": "orbit", "pendulum": "pendulum",
                "pulse": "oscillating_stretch", "flow": "linear_flow", "bounce": "bounce", "still": "static"}
    assert m["type"] == expected[kind]
    if kind == "flight":
        assert np.linalg.norm(m["omega"]) <= family.MAX_TURN_RATE + 1e-12
        assert _in(-m["gravity"][2], family.GRAVITY) and m["gravity"][:2] == [0.0, 0.0]
        assert _in(m["velocity"][2] / -m["gravity"][2], family.APEX_TIME)
    elif kind == "spin":
        assert _in(np.linalg.norm(m["omega"]), family.SPIN_RATE) and m["velocity"] == [0.0, 0.0, 0.0]
    elif kind == "orbit":
        orbit, spin = np.linalg.norm(m["orbit"]), np.linalg.norm(m["spin"])
        assert _in(orbit, family.ORBIT_RATE) and _in(spin, family.SPIN_RATE)
        assert abs(orbit - spin) >= family.ORBIT_SPIN_GAP
        assert _in(np.linalg.norm(np.subtract(m["centre"], m["pivot"])), family.ORBIT_RADIUS)
    elif kind == "pendulum":
        assert _in(m["amplitude"], family.PENDULUM_AMPLITUDE) and _in(m["omega"], family.OSCILLATION_RATE)
        assert m["axis"][2] == 0.0
    elif kind == "pulse":
        assert all(_in(abs(k), family.PULSE_AMPLITUDE) for k in m["amplitude"])
        assert _in(m["omega"], family.OSCILLATION_RATE)
    elif kind == "flow":
        L = np.array(m["generator"])
        assert abs(np.trace(L)) < 1e-12 and np.allclose(L, L.T)
        assert _in(np.abs(L).max(), family.FLOW_RATE)
    elif kind == "bounce":
        assert _in(m["restitution"], family.RESTITUTION) and _in(m["gravity"], family.GRAVITY)
        assert abs(m["spin"]) <= family.BOUNCE_SPIN_RATE
        first_bounce = BounceMotion(**{k: v for k, v in m.items() if k != "type"}).first_impact()[0]
        assert first_bounce <= family.LAST_FIRST_BOUNCE


def test_bodies_stay_in_view_apart_and_above_the_ground(draws):
    rng = np.random.default_rng(0)
    times = np.linspace(0.0, 1.0, 101)  # finer than the draw's checks, future included
    for d in draws[:30]:
        scene = family.scene_from_parameters(d)
        cameras = family.rig_cameras(d)
        solids = [b for b in scene.bodies if b.primitive != "plane"]
        surfaces = [b.sample_surface(200, rng)[0] for b in solids]
        for t in times:
            points = []
            for body, p in zip(solids, surfaces):
                L, o = body.to_world(t)
                points.append(p @ L.T + o)
            for camera in cameras:
                uv, depth = camera.project(np.concatenate(points))
                assert np.all(depth > 0)
                assert np.all((uv >= 0) & (uv <= [camera.width, camera.height])), (d["seed"], t)
            for i, body in enumerate(solids):
                for j, x in enumerate(points):
                    if i != j:
                        assert np.all(body.outside_distance(x, t) > 0), (d["seed"], t, i, j)
            if d["ground"] is not None:
                assert np.concatenate(points)[:, 2].min() >= d["ground"]["centre"][2] - 1e-9, (d["seed"], t)


def test_declared_effects_and_incompressibility_follow_the_motions(draws):
    for d in draws[:40]:
        scene = family.scene_from_parameters(d)
        kinds = set(d["kinds"])
        assert ("gravity" in scene.effects) == bool(kinds & {"flight", "bounce"})
        assert ("oscillation" in scene.effects) == bool(kinds & {"orbit", "pendulum", "pulse"})
        assert ("static" in scene.effects) == ("still" in kinds or d["ground"] is not None)
        if kinds <= {"flight", "spin", "orbit", "pendulum", "bounce", "still", "flow"}:
            assert scene.incompressible  # rigid motions and trace-free flows keep volume


# --- the new motions' exact truth -------------------------------------------------------------

NEW_MOTIONS = {
    "orbit": OrbitMotion((0.1, -0.2, 0.3), (0.6, 0.1, 0.2), (0.3, -0.5, 4.0), (2.0, 1.0, -3.0)),
    "pendulum": PendulumMotion((0.2, 0.1, 0.8), (1.0, 2.0, 0.0), 0.7, 9.0, 1.1),
    "oscillating_stretch": OscillatingStretchMotion(
        (0.3, -0.1, 0.2), Rotation.from_rotvec([0.3, -0.5, 0.8]).as_matrix(), (0.3, -0.2, 0.25), 7.0, (0.4, 2.5, 5.0)),
    "bounce": BounceMotion((0.2, -0.3, 0.4), (0.5, -0.4, 1.2), 9.0, -0.6, 0.7, 4.0),
}


def _bounce_times(motion, until=2.0):
    start, speed = motion.first_impact()
    times = []
    while start < until and speed > 1e-9:
        times.append(start)
        start, speed = start + 2.0 * speed / motion.gravity, speed * motion.restitution
    return np.array(times)


@pytest.mark.parametrize("kind", sorted(NEW_MOTIONS))
def test_new_motions_match_finite_differences(kind):
    motion = NEW_MOTIONS[kind]
    x0 = np.random.default_rng(1).normal(size=(8, 3))
    np.testing.assert_array_equal(motion.position(x0, 0.0), x0)
    bounces = _bounce_times(motion) if kind == "bounce" else np.array([])
    for t in np.linspace(0.0, 1.5, 31):
        if len(bounces) and np.abs(bounces - t).min() < 10 * H:
            continue  # the velocity jumps at a bounce
        x = motion.position(x0, t)
        dxdt = (motion.position(x0, t + H) - motion.position(x0, t - H)) / (2 * H)
        np.testing.assert_allclose(motion.velocity(x, t), dxdt, atol=FD_TOL)
        dvdt = (motion.velocity(motion.position(x0, t + H), t + H)
                - motion.velocity(motion.position(x0, t - H), t - H)) / (2 * H)
        np.testing.assert_allclose(motion.acceleration(x, t), dvdt, atol=FD_ACC_TOL)
        np.testing.assert_allclose(motion.canonical(x, t), x0, atol=1e-12)


def test_a_bounce_keeps_the_position_and_reverses_the_vertical_velocity():
    motion = NEW_MOTIONS["bounce"]
    bounces = _bounce_times(motion)
    assert len(bounces) >= 2
    x0 = np.array([[0.2, -0.3, 0.4]])  # the centre, which meets the floor
    for tb in bounces:
        before, after = motion.position(x0, tb - 1e-9), motion.position(x0, tb + 1e-9)
        np.testing.assert_allclose(before, after, atol=1e-7)
        np.testing.assert_allclose(motion.position(x0, tb)[0, 2], motion.floor, atol=1e-12)
        v_before = motion.velocity(before, tb - 1e-9)[0, 2]
        v_after = motion.velocity(motion.position(x0, tb), tb)[0, 2]  # the velocity just after
        np.testing.assert_allclose(v_after, -motion.restitution * v_before, rtol=1e-6)
    rest = bounces[0] + 2.0 * motion.first_impact()[1] / (motion.gravity * (1.0 - motion.restitution))
    assert motion.position(x0, rest + 0.1)[0, 2] == motion.floor
    np.testing.assert_array_equal(motion.velocity(x0, rest + 0.1)[:, 2], [0.0])


@pytest.mark.parametrize("kind", sorted(NEW_MOTIONS))
def test_new_motions_round_trip_exactly_through_json(kind):
    motion = NEW_MOTIONS[kind]
    rebuilt = motion_from_dict(json.loads(json.dumps(motion.to_dict())))
    assert rebuilt.to_dict() == motion.to_dict()
    for t in (0.0, 0.37, 1.3):
        for a, b in zip(rebuilt.affine(t) + rebuilt.rate(t), motion.affine(t) + motion.rate(t)):
            np.testing.assert_array_equal(a, b)


def test_new_motions_refuse_bad_parameters():
    with pytest.raises(ValueError, match="^restitution: "):
        BounceMotion((0, 0, 1), (0, 0, 0), 9.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="^floor: "):
        BounceMotion((0, 0, 1), (0, 0, 0), 9.0, 2.0, 0.5)
    with pytest.raises(ValueError, match="^axis: "):
        PendulumMotion((0, 0, 1), (0, 0, 0), 0.5, 3.0)
    with pytest.raises(ValueError, match="^axes: "):
        OscillatingStretchMotion((0, 0, 0), 2 * np.eye(3), (0.1, 0.1, 0.1), 3.0)
    with pytest.raises(ValueError, match="^description: "):
        motion_from_dict({"type": "orbit", "pivot": [0, 0, 0]})


def test_drawn_scenes_round_trip_through_their_description(draws):
    x = np.random.default_rng(2).uniform(-1.5, 1.5, size=(300, 3))
    for d in draws[:40]:
        scene = family.scene_from_parameters(d)
        rebuilt = AnalyticScene.from_dict(json.loads(json.dumps(scene.to_dict())))
        assert rebuilt.to_dict() == scene.to_dict()
        for t in (0.3, 0.95):
            np.testing.assert_array_equal(rebuilt.velocity(x, t, margin=np.inf), scene.velocity(x, t, margin=np.inf))
        solids = scene.bodies[:len(d["bodies"])]
        assert [body_from_dict(b).to_dict() for b in d["bodies"]] == [b.to_dict() for b in solids]


# --- on disk ----------------------------------------------------------------------------------


def test_a_small_random_scene_loads_with_its_window_background_and_truth(tmp_path):
    seed = SMALL_SEED
    params = family.draw_parameters(seed)
    out = _tiny(seed, tmp_path / "s", n_frames=8)
    meta = json.loads((out / "scene.json").read_text())
    assert meta["family"]["seed"] == seed and meta["family"]["parameters"] == params
    assert meta["family"]["overrides"] == {"resolution": 16, "n_frames": 8}
    times, max_time = family.frame_times(8, params["future_fraction"])
    assert meta["max_time"] == max_time and meta["name"] == f"random-{seed}"

    data = load_scene(out)
    assert data.max_time == max_time
    np.testing.assert_array_equal(data.background, family.BACKGROUND[params["background"]])
    assert data.width == data.height == 16
    assert {f.time for f in data.train} == {t for t in times if t <= max_time}
    assert {f.time for f in data.extrapolation} == {t for t in times if t > max_time}
    # A window or background given explicitly wins; the defaults count as not given.
    assert load_scene(out, max_time=0.5).max_time == 0.5
    assert load_scene(out, max_time=0.75).max_time == max_time
    np.testing.assert_array_equal(load_scene(out, background=(0.5, 0.5, 0.5)).background, 0.5)

    truth, original = load_ground_truth(out), family.scene_from_parameters(params)
    x = np.random.default_rng(3).uniform(-1.5, 1.5, size=(200, 3))
    for t in (0.1, 0.9):
        np.testing.assert_array_equal(truth.velocity(x, t, margin=np.inf), original.velocity(x, t, margin=np.inf))
        np.testing.assert_array_equal(truth.position(x, t, margin=np.inf), original.position(x, t, margin=np.inf))


def test_bad_window_or_background_in_scene_json_is_a_data_error(tmp_path):
    out = _tiny(SMALL_SEED, tmp_path / "s", n_frames=4)
    meta = json.loads((out / "scene.json").read_text())
    for key, value in (("max_time", 1.5), ("background", "grey")):
        (out / "scene.json").write_text(json.dumps({**meta, key: value}))
        with pytest.raises(DataError, match=key):
            load_scene(out)


def test_make_scene_random_on_the_command_line(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["make-scene", "--random", str(SMALL_SEED), "--out", str(tmp_path / "r")])
    assert result.exit_code == 0, result.output
    params = family.draw_parameters(SMALL_SEED)
    data = load_scene(tmp_path / "r")
    assert data.width == params["resolution"] and data.max_time == params["max_time"]
    both = runner.invoke(app, ["make-scene", "spin", "--random", "3", "--out", str(tmp_path / "x")])
    assert both.exit_code == 2 and "error: NAME" in both.output


def test_random_refuses_the_flags_it_would_ignore(tmp_path):
    from typer.testing import CliRunner

    from velogauss.cli import app

    for args in (["--random", "3", "--resolution", "64"], ["--random", "3", "--monocular"], ["--random", "-1"]):
        result = CliRunner().invoke(app, ["make-scene", *args, "--out", str(tmp_path / "s")])
        assert result.exit_code == 2 and "--random" in result.output, result.output
        assert not (tmp_path / "s").exists()
