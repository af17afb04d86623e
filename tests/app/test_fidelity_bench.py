"""The fidelity study (velogauss.bench.fidelity) and its diagnostic of the bodies' centres (velogauss.diagnose.centre)."""

import json

import numpy as np
import pytest
import torch

from velogauss.diagnose.centre import centre_errors, centre_motion, reference_offsets
from velogauss.bench.fidelity import VARIANTS, acceleration_scores, pareto_front, pareto_plot, run_one
from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.model import build_model, scene_spec
from velogauss.scenes import load_ground_truth, make_scene
from velogauss.scenes.bodies import Body, Texture
from velogauss.scenes.trajectories import RigidMotion
from velogauss.scenes.scene import AnalyticScene


def test_pareto_front_keeps_runs_better_than_every_cheaper_one():
    costs, psnr = [10, 20, 30, 40], [20.0, 19.0, 22.0, 21.5]
    assert pareto_front(costs, psnr, 1.0) == [(10, 20.0), (30, 22.0)]
    errors = [0.3, 0.2, 0.25, 0.1]
    assert pareto_front(costs, errors, -1.0) == [(10, 0.3), (20, 0.2), (40, 0.1)]


def test_pareto_plot_groups_seeds_and_counts_the_defaults_as_their_cost_point(tmp_path):
    def record(variant, seed, wall, extrap, vel, scene="toss"):
        return {"scene": scene, "level": "full", "variant": variant, "seed": seed, "wall_s": wall,
                "extrap_psnr": extrap, "vel_future": vel}

    records = [record("cost-v1-i2000", 0, 100.0, 20.0, 0.3), record("cost-v1-i2000", 1, 110.0, 21.0, 0.2),
               record("a", 0, 200.0, 22.0, 0.15), record("a", 1, 220.0, 23.0, 0.25),
               record("a", 0, 999.0, 1.0, 9.0, scene="multi"), record("b", 0, 50.0, 1.0, 9.0)]
    table = pareto_plot(records, tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 0
    rows = table.splitlines()[2:]
    assert len(rows) == 2  # other scenes and non-cost variants are left out
    assert pareto_plot(records, tmp_path / "m.png", scene="multi").splitlines()[2].startswith("| cost-v3-i3000 | 1 | 999")
    assert rows[0].startswith("| cost-v1-i2000 | 2 | 105 (100–110) | 20.50 (20.00–21.00) | 0.250 (0.200–0.300)")
    assert rows[1].startswith("| cost-v3-i3000 | 2 | 210 (200–220) | 22.50 (22.00–23.00) |")


def test_acceleration_scores_against_a_thrown_box(tmp_path):
    """A box thrown without spin accelerates at g everywhere: Q_0 = g in the translation
    columns (every pattern) is exact, whatever the mixing weights; Q = 0 is wrong by |g|/|g|."""
    make_scene("toss", tmp_path / "toss", resolution=16, n_views=2, n_times=3, n_points=50, n_heldout=1)
    scene = load_scene(tmp_path / "toss")
    cfg = load_config(None, ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2"])
    model = build_model(cfg, scene_spec(cfg, scene.metadata), scene.points, scene.point_colors,
                        np.random.default_rng(0))
    box = Body("box", "box", centre=(0.0, 0.0, 0.0), size=(0.4, 0.3, 0.2), rotation=np.eye(3),
               texture=Texture("checker", ((1, 0, 0), (0, 0, 1))),
               motion=RigidMotion(centre=(0.0, 0.0, 0.0), velocity=(1.0, 0.0, 4.0), gravity=(0.0, 0.0, -8.0)))
    thrown = AnalyticScene("thrown", [box], effects=["translation", "gravity"], incompressible=True)
    with torch.no_grad():
        model.motion.acc.zero_()
        model.motion.acc[0, :, 2] = -8.0
    exact = acceleration_scores(model, thrown, 0.75)
    assert exact["acc_observed"] == pytest.approx(0.0, abs=1e-6)
    assert exact["acc_future"] == pytest.approx(0.0, abs=1e-6)
    with torch.no_grad():
        model.motion.acc.zero_()
    assert acceleration_scores(model, thrown, 0.75) == pytest.approx({"acc_observed": 1.0, "acc_future": 1.0})


# The toss's declared effects (translation, rotation, gravity) and the rigid patterns they called
# for when "auto" read scene.json: the centre diagnostics read rigid patterns.
RIGID = ["model.effects=declared", "model.patterns=rigid"]


def _small_toss_model(tmp_path, overrides=()):
    """(model, scene) of a small generated toss, the model freshly built with `overrides`."""
    if not (tmp_path / "toss").is_dir():
        make_scene("toss", tmp_path / "toss", resolution=16, n_views=2, n_times=3, n_points=50, n_heldout=1)
    data = load_scene(tmp_path / "toss")
    cfg = load_config(None, ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2",
                             *RIGID, *overrides])
    model = build_model(cfg, scene_spec(cfg, data.metadata), data.points, data.point_colors,
                        np.random.default_rng(0))
    return model, load_ground_truth(tmp_path / "toss")


def _thrown_box_with_rigid_patterns(tmp_path):
    """(model, scene) of a small toss whose rigid patterns (VG-COEF-RIGID) are all set to the
    box's own spin and its centre at the knots: the true motion."""
    model, scene = _small_toss_model(tmp_path)
    (box,) = scene.bodies
    T = model.spec.max_time
    knots = [scene.position(box.centre[None], tau, margin=np.inf)[0] for tau in (0.0, T / 2, T)]
    with torch.no_grad():
        model.motion.time.copy_(torch.as_tensor(np.concatenate([box.motion.omega, *knots]), dtype=torch.float32))
    return model, scene


def test_centre_errors_of_a_thrown_spinning_box(tmp_path):
    """The true rigid patterns give the box's centre its velocity exactly at every time, in
    the window and past it; a still model is wrong by the whole velocity."""
    model, scene = _thrown_box_with_rigid_patterns(tmp_path)
    T = model.spec.max_time
    times = (0.0, T / 3, T, 1.0)
    rows = centre_errors(model, scene, times)["box"]
    assert [t for t, _, _ in rows] == pytest.approx(times)
    for _, error, speed in rows:
        assert np.linalg.norm(error) < 1e-5 * speed
    with torch.no_grad():
        model.motion.time.zero_()
    for t, error, speed in centre_errors(model, scene, times)["box"]:
        assert np.linalg.norm(error) == pytest.approx(speed, rel=1e-6)


def test_centre_motion_of_a_thrown_spinning_box(tmp_path):
    """The true rigid patterns give the box's spin (2 rad per unit time about a tilted axis)
    and gravity (0, 0, -8) as its centre's mean acceleration in the window and past it; a
    still model gives zero for each, against the same truth."""
    model, scene = _thrown_box_with_rigid_patterns(tmp_path)
    (box,) = scene.bodies
    T = model.spec.max_time
    motion = centre_motion(model, scene, T)["box"]
    assert set(motion) == {"spin", "acc_window", "acc_future"}
    gravity = np.array([0.0, 0.0, -8.0])
    np.testing.assert_allclose(motion["spin"][1], box.motion.omega, atol=1e-9)
    np.testing.assert_allclose(motion["spin"][0], box.motion.omega, atol=1e-4)
    for key in ("acc_window", "acc_future"):
        np.testing.assert_allclose(motion[key][1], gravity, atol=1e-9)
        np.testing.assert_allclose(motion[key][0], gravity, atol=1e-4)
    with torch.no_grad():
        model.motion.time.zero_()
    for learned, truth in centre_motion(model, scene, T)["box"].values():
        np.testing.assert_allclose(learned, 0.0, atol=1e-9)
        assert np.linalg.norm(truth) > 1.0


def test_reference_offsets_measure_the_centre_off_the_spin_axis(tmp_path):
    """The true knots are on the axis through the box's centre (offset 0); knots moved along
    the spin axis give the same field and offset 0; knots moved by 0.2 across it, 0.2."""
    model, scene = _thrown_box_with_rigid_patterns(tmp_path)
    (box,) = scene.bodies
    assert [t for t, _ in reference_offsets(model, scene)["box"]] == pytest.approx([0.0, 0.375, 0.75])
    assert max(offset for _, offset in reference_offsets(model, scene)["box"]) < 1e-6
    axis = box.motion.omega / np.linalg.norm(box.motion.omega)
    across = np.cross(axis, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    for shift, expected in ((0.3 * axis, 0.0), (0.2 * across, 0.2)):
        moved = model.motion.time.detach().clone()
        moved[:, 3:] += torch.as_tensor(np.tile(shift, 3), dtype=torch.float32)
        with torch.no_grad():
            original = model.motion.time.detach().clone()
            model.motion.time.copy_(moved)
        offsets = [offset for _, offset in reference_offsets(model, scene)["box"]]
        np.testing.assert_allclose(offsets, expected, atol=1e-6)
        with torch.no_grad():
            model.motion.time.copy_(original)
    mlp, _ = _small_toss_model(tmp_path, ["model.patterns=mlp"])
    with pytest.raises(ValueError, match="rigid"):
        reference_offsets(mlp, scene)


def test_the_variants_run_the_current_defaults_and_their_ablations():
    assert VARIANTS["a"] == [] and VARIANTS["b"] == ["model.scheme=adf-step"]
    for ablation in ("no-gpc", "no-adf", "no-pds", "deform-only"):
        assert [f"model.ablation={ablation}"] in VARIANTS.values()
    for overrides in VARIANTS.values():
        load_config(None, overrides)  # every one a valid config


def test_a_variant_that_cannot_be_run_says_why(tmp_path):
    """A record of an earlier version's variant is read from the cache but never retrained;
    an unknown variant lists the choices; a record under a name this version runs with other
    overrides is refused, not passed off as its result. Nothing trains or is written."""
    with pytest.raises(ValueError, match="'a-typo' cannot be run: choose from .*a-no-gpc"):
        run_one("toss", "full", "a-typo", 0, tmp_path)
    assert not any(tmp_path.iterdir())
    (tmp_path / "results").mkdir()
    old = {"scene": "toss", "level": "full", "variant": "a-classic", "seed": 0, "extrap_psnr": 36.11,
           "overrides": ["model.rasterize_mode=classic"]}
    (tmp_path / "results" / "toss-full-a-classic-s0.json").write_text(json.dumps(old))
    assert run_one("toss", "full", "a-classic", 0, tmp_path) == old
    renamed = {**old, "variant": "a-no-gpc", "overrides": ["model.ablation=no-gpc", "model.rasterize_mode=classic"]}
    (tmp_path / "results" / "toss-full-a-no-gpc-s0.json").write_text(json.dumps(renamed))
    with pytest.raises(ValueError, match="toss-full-a-no-gpc-s0.json: recorded with the overrides .*classic"):
        run_one("toss", "full", "a-no-gpc", 0, tmp_path)
    current = {**renamed, "overrides": ["model.ablation=no-gpc"]}
    (tmp_path / "results" / "toss-full-a-no-gpc-s0.json").write_text(json.dumps(current))
    assert run_one("toss", "full", "a-no-gpc", 0, tmp_path) == current


def test_the_centre_report_reads_a_trained_run(tmp_path):
    """`velogauss diagnose centre RUN --data SCENE`'s report on a (briefly) trained toss: one
    line of velocity errors and one each for the spin, the two accelerations and the knots'
    offset, per body."""
    from velogauss.diagnose.centre import report
    from velogauss.train import loop

    make_scene("toss", tmp_path / "toss", resolution=16, n_views=2, n_times=3, n_points=50, n_heldout=1)
    cfg = load_config(None, ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2",
                             "train.iterations=4", "train.warmup=2", "train.curriculum=1", "physics.n_points=16",
                             "train.eval_every=0", *RIGID])
    loop.train(cfg, load_scene(tmp_path / "toss"), tmp_path / "run", progress=False)
    lines = list(report(tmp_path / "run", tmp_path / "toss", [0.0, 1.0]))
    assert [line.split("] ")[1].split(":")[0].split("  ")[0] for line in lines] == [
        "velocity error", "spin", "acc_window", "acc_future", "rigid centre's offset from the axis through the true centre"]
    assert all(line.startswith(f"{tmp_path / 'run'} [box]") for line in lines)
    assert "t=0:" in lines[0] and "t=1:" in lines[0]
