"""A model trained from a generated scene written in the nerfstudio or Panoptic layout is scored on the
generator's true motion (issue 39: the loaders are tested on scenes whose ground-truth motion scores).

The expected scores are those of the same model against the D-NeRF twin's ground truth: the truth is the
generator's, whichever layout carried it; nothing is computed by the code under test alone."""

import numpy as np
import pytest

from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.evaluate import evaluate_model, velocity_error
from velogauss.scenes import load_ground_truth, make_scene
from velogauss.train.loop import train

SIZE = dict(resolution=16, n_views=4, n_heldout=1, n_times=9, supersample=1, n_points=50)
SHORT = ["train.iterations=8", "train.warmup=2", "train.curriculum=3", "train.eval_every=0",
         "train.checkpoint_every=0", "densify.start=2", "densify.every=4", "densify.until=6",
         "physics.n_points=32", "physics.ramp=2", "model.hidden=16", "model.depth=1", "model.n_patterns=4",
         "model.code_dim=4", "model.patterns=mlp", "train.threads=1"]


@pytest.mark.parametrize("layout", ["nerfstudio", "panoptic"])
def test_a_model_trained_from_the_layout_is_scored_on_the_true_motion(layout, tmp_path):
    twin = make_scene("toss", tmp_path / "dnerf", **SIZE)
    root = make_scene("toss", tmp_path / layout, **SIZE, format=layout)
    scene = load_scene(root)
    model = train(load_config(None, SHORT), scene, tmp_path / "run", progress=False)
    result = evaluate_model(model, scene, ground_truth=load_ground_truth(root))  # scene.json travels along
    velocity = result["motion"]["velocity"]
    assert all(np.isfinite(velocity[part]["relative_l2"]) for part in ("observed", "future"))
    assert result["motion"]["trajectory"]["gaussians"] > 0
    expected = velocity_error(model, load_ground_truth(twin), scene.max_time)
    assert expected["observed"] == velocity["observed"] and expected["future"] == velocity["future"]
