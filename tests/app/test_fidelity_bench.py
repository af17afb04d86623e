"""The fidelity study's accuracy-against-time summary (velogauss.bench.fidelity)."""

import numpy as np
import pytest
import torch

from velogauss.bench.fidelity import acceleration_scores, pareto_front, pareto_plot
from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.model import build_model, scene_profile
from velogauss.scenes import make_scene
from velogauss.scenes.bodies import Body, Texture
from velogauss.scenes.motions import RigidMotion
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
    model = build_model(cfg, scene_profile(cfg, scene.metadata), scene.points, scene.point_colors,
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
