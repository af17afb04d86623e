"""velogauss.train.centres: rigid patterns' centres anchored on the body (VG-COEF-RIGID, "Centre")."""

import numpy as np
import pytest
import torch

from velogauss.config import ModelConfig, load_config
from velogauss.data import load_scene
from velogauss.model import build_model, scene_spec
from velogauss.model.spec import resolve_motion_spec
from velogauss.scenes import make_scene
from velogauss.train import loop
from velogauss.train.centres import anchor_centres, hull_centroid, resolve_rigid_centre
from velogauss_core.constants import RIGID_HULL_OPACITY

TINY = ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2"]
# Rigid patterns on the toss's declared effects (translation, rotation, gravity: one body, a
# parabola): "auto" would read neither the declaration nor pick a form without a backtest.
RIGID = ["model.effects=declared", "model.patterns=rigid"]


def _toss(tmp_path):
    make_scene("toss", tmp_path / "toss", resolution=16, n_views=2, n_times=3, n_points=60, n_heldout=1)
    return load_scene(tmp_path / "toss")


def _model(data, overrides=()):
    cfg = load_config(None, [*TINY, *RIGID, *overrides])
    return build_model(cfg, scene_spec(cfg, data.metadata), data.points, data.point_colors,
                       np.random.default_rng(0))


def test_hull_centroid_is_the_centre_of_the_volume_not_of_the_points():
    """A cube's corners plus many points crowded on one face: their mean leans to that face,
    the centroid of the enclosed volume is the cube's centre."""
    rng = np.random.default_rng(0)
    corners = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    face = np.column_stack([rng.uniform(0, 1, 500), rng.uniform(0, 1, 500), np.ones(500)])
    points = np.vstack([corners, face]) + np.array([2.0, -1.0, 0.5])
    np.testing.assert_allclose(hull_centroid(points), [2.5, -0.5, 1.0], atol=1e-12)
    assert points.mean(0)[2] > 1.4
    # A flat set spans no volume: its mean.
    flat = np.column_stack([rng.uniform(0, 1, 20), rng.uniform(0, 1, 20), np.zeros(20)])
    np.testing.assert_allclose(hull_centroid(flat), flat.mean(0))
    np.testing.assert_allclose(hull_centroid(corners[:2]), corners[:2].mean(0))


@pytest.mark.spec("VG-COEF-RIGID")
def test_the_knots_move_to_the_hull_centroid_and_the_motion_stays_still(tmp_path):
    data = _toss(tmp_path)
    model = _model(data)
    g = model.gaussians
    with torch.no_grad():  # a faint half, left out of the hull
        logits = torch.full_like(g.opacity_logits, 2.0)
        logits.reshape(-1)[::2] = -2.0
        g.opacity_logits.copy_(logits)
    opacity = g.opacities.reshape(-1).detach().numpy()
    opaque = opacity >= RIGID_HULL_OPACITY * opacity.max()
    assert 0 < opaque.sum() < len(opaque)
    centre = anchor_centres(model)
    np.testing.assert_allclose(centre, hull_centroid(g.means.detach().numpy()[opaque].astype(np.float64)))
    B = model.motion.time.detach().numpy()
    assert np.all(B[:, :3] == 0.0)
    np.testing.assert_array_equal(B[:, 3:], np.tile(centre.astype(np.float32), (B.shape[0], 3)))
    # The box's surface points bound it: its centroid is its centre at t = 0.
    np.testing.assert_allclose(centre, [-0.5, 0.0, -0.5], atol=0.05)
    # Still patterns, wherever their centres: every Gaussian stays at its canonical state (to
    # the float32 rounding of c'(t), the knots times Lagrange weights that cancel).
    for t in (0.3, 0.75, 1.0):
        torch.testing.assert_close(model.state_at(t)[0], g.means, rtol=0.0, atol=1e-6)


def test_anchoring_refuses_moving_patterns_and_other_forms(tmp_path):
    data = _toss(tmp_path)
    model = _model(data)
    with torch.no_grad():
        model.motion.time[0, 0] = 0.5
    with pytest.raises(ValueError, match="model.motion.time"):
        anchor_centres(model)
    with pytest.raises(ValueError, match="rigid"):
        anchor_centres(_model(data, ["model.patterns=mlp"]))
    still = _model(data)
    still.set_moving(torch.zeros(len(still.gaussians.means), dtype=torch.bool))
    with pytest.raises(ValueError, match="model.moving"):
        anchor_centres(still)


def test_auto_anchors_rigid_patterns_of_one_body():
    def spec(*effects, patterns="rigid"):
        return resolve_motion_spec(ModelConfig(effects=effects, incompressible=True, patterns=patterns), None, 1.0)

    toss = spec("translation", "rotation", "gravity")
    spin = spec("translation", "rotation")
    multi = spec("translation", "rotation", "gravity", "static")
    stretch = spec("stretch", patterns="auto")
    assert resolve_rigid_centre("auto", toss, "auto") == "hull"
    assert resolve_rigid_centre("auto", spin, "auto") == "learned"  # a centre on a line (2 knots)
    assert resolve_rigid_centre("hull", spin, "auto") == "hull"
    assert resolve_rigid_centre("auto", multi, "auto") == "learned"  # regions start apart: not one body
    assert resolve_rigid_centre("auto", multi, "uniform") == "hull"
    assert resolve_rigid_centre("auto", stretch, "auto") == "learned"
    # Patterns left "auto" at resolution (no backtest) are the time network: nothing to anchor.
    unchosen = spec("translation", "rotation", "gravity", patterns="auto")
    assert resolve_rigid_centre("auto", unchosen, "uniform") == "learned"
    with pytest.raises(ValueError, match="model.rigid_centre"):
        resolve_rigid_centre("hull", stretch, "auto")
    with pytest.raises(ValueError, match="model.rigid_centre"):
        resolve_rigid_centre("hull", unchosen, "auto")
    with pytest.raises(ValueError, match="rigid_centre"):
        load_config(None, ["model.rigid_centre=middle"])


@pytest.mark.spec("VG-COEF-RIGID")
@pytest.mark.parametrize("centre", ["learned", "hull"])
def test_training_anchors_the_centre_when_the_motion_starts_and_holds_it(tmp_path, centre):
    data = _toss(tmp_path)
    # "auto" learns the centres of patterns that start apart (not one body).
    choice = ["model.rigid_centre=hull"] if centre == "hull" else ["model.mixing_init=clusters"]
    cfg = load_config(None, [*TINY, *RIGID, "train.iterations=6", "train.warmup=2", "train.curriculum=1",
                             "physics.n_points=16", *choice])
    trainer, _ = loop.prepare(cfg, data, tmp_path / "run")
    B = trainer.model.motion.time
    for it in range(2):  # the warm-up: the patterns are frozen at B = 0
        trainer.step(it)
        trainer.adapt_gaussians(it + 1)
    assert not bool(B.any())
    trainer.step(2)
    assert (trainer.knot_mask is not None) == (centre == "hull")
    anchored = B.detach()[:, 3:6].clone()
    for it in range(3, 6):
        trainer.step(it)
    if centre == "learned":
        assert float(anchored.abs().max()) < 0.1  # one Adam step of the acceleration's rate from 0
    else:
        np.testing.assert_allclose(anchored.numpy(), np.tile([-0.5, 0.0, -0.5], (3, 1)), atol=0.05)
        torch.testing.assert_close(B.detach()[:, 3:6], anchored, rtol=0.0, atol=0.0)  # held
    assert not torch.equal(B.detach()[:, 6:], B.detach()[:, 3:6])  # the later knots train


@pytest.mark.spec("VG-COEF-RIGID")
def test_a_resumed_run_keeps_its_anchored_centre(tmp_path):
    data = _toss(tmp_path)
    tiny = [*TINY, *RIGID, "train.warmup=2", "train.curriculum=1", "physics.n_points=16", "train.eval_every=0",
            "train.checkpoint_every=4", "model.rigid_centre=hull"]
    first = loop.train(load_config(None, [*tiny, "train.iterations=4"]), data, tmp_path / "run", progress=False)
    anchored = first.motion.time.detach()[:, 3:6].clone()
    resumed = loop.train(load_config(None, [*tiny, "train.iterations=7"]), data, tmp_path / "run", resume=True,
                         progress=False)
    B = resumed.motion.time.detach()
    torch.testing.assert_close(B[:, 3:6], anchored, rtol=0.0, atol=0.0)
    assert not torch.equal(B[:, 6:], first.motion.time.detach()[:, 6:])  # and the rest kept training
