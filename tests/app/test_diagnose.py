"""The `velogauss diagnose` commands on a briefly trained run (the diagnostics themselves:
tests/app/test_visibility.py, and the centre's in tests/app/test_fidelity_bench.py)."""

import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.scenes import make_scene
from velogauss.train import loop


@pytest.fixture(scope="module")
def trained_toss(tmp_path_factory):
    """(run folder, scene folder) of a toss trained for 4 iterations, with its declared effects
    and rigid patterns (what "auto" resolved to when it read scene.json; the centre command reads
    rigid patterns' knots)."""
    root = tmp_path_factory.mktemp("diagnose")
    make_scene("toss", root / "toss", resolution=16, n_views=2, n_times=3, n_points=50, n_heldout=1)
    cfg = load_config(None, ["model.hidden=8", "model.depth=1", "model.n_patterns=3", "model.code_dim=2",
                             "train.iterations=4", "train.warmup=2", "train.curriculum=1", "physics.n_points=16",
                             "train.eval_every=0", "model.effects=declared", "model.patterns=rigid"])
    loop.train(cfg, load_scene(root / "toss"), root / "run", progress=False)
    return root / "run", root / "toss"


def test_the_centre_command_reads_a_trained_run(trained_toss):
    """`velogauss diagnose centre RUN --data SCENE`: one line of velocity errors and one each for
    the spin, the two accelerations and the knots' offset, per body."""
    run, scene = trained_toss
    result = CliRunner().invoke(app, ["diagnose", "centre", str(run), "--data", str(scene), "--times", "0,1"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [line.split("] ")[1].split(":")[0].split("  ")[0] for line in lines] == [
        "velocity error", "spin", "acc_window", "acc_future", "rigid centre's offset from the axis through the true centre"]
    assert all(line.startswith(f"{run} [box]") for line in lines)
    assert "t=0:" in lines[0] and "t=1:" in lines[0]


def test_the_visibility_command_reads_a_trained_run(trained_toss):
    """`velogauss diagnose visibility RUN --data SCENE`: a markdown table with a row per body and
    part that has points, and the same for all bodies together."""
    run, scene = trained_toss
    result = CliRunner().invoke(app, ["diagnose", "visibility", str(run), "--data", str(scene)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[:2] == ["| run | body | part | points | vel. err obs | vel. err fut |", "|---|---|---|---:|---:|---:|"]
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]
    assert rows and all(row[0] == str(run) and row[2] in ("seen", "unseen") and int(row[3]) > 0 for row in rows)
    assert {row[1] for row in rows} == {"box", "all"}


def test_the_slip_command_reads_a_trained_run(trained_toss):
    """`velogauss diagnose slip RUN --data SCENE --times 0.5,1`: a markdown table with a row per
    moving body and time; the box turns 2 rad per unit time, so by t = 1 by 114.6 degrees."""
    run, scene = trained_toss
    result = CliRunner().invoke(app, ["diagnose", "slip", str(run), "--data", str(scene), "--times", "0.5,1"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].startswith("| run | body | t | Gaussians | body's turn")
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines[2:]]
    assert [(row[0], row[1], row[2]) for row in rows] == [(str(run), "box", "0.5"), (str(run), "box", "1")]
    assert all(int(row[3]) >= 3 for row in rows)
    assert float(rows[1][4]) == pytest.approx(114.6, abs=0.1)


def test_the_slip_command_names_a_bad_time(trained_toss):
    run, scene = trained_toss
    result = CliRunner().invoke(app, ["diagnose", "slip", str(run), "--data", str(scene), "--times", "0.5,soon"])
    assert result.exit_code == 2
    assert "--times" in result.output and "soon" in result.output
