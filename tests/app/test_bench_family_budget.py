"""`velogauss bench family budgets` and `pareto` (velogauss/bench/family_budget.py): the grid
trains each scene's default and shorter runs under the names `pareto` reads back; `pareto`'s
table on a hand-written study folder, against numbers worked out by hand below."""

import json

import pytest
from typer.testing import CliRunner

from velogauss.bench import family, family_budget
from velogauss.cli import app
from velogauss.scenes.family import make_random_scene
from velogauss.sweep.grid import load_grid


def bench_family(*args, code=0):
    result = CliRunner().invoke(app, ["bench", "family", *map(str, args)])
    assert result.exit_code == code, result.output
    return result


def write_run(folder, iterations, elapsed, probe, vel_obs, vel_fut, extrap, frozen):
    """The files of a finished run that `pareto` reads (probe None: no motion_form.json)."""
    folder.mkdir(parents=True)
    (folder / "metrics.json").write_text(json.dumps({
        "splits": {"extrapolation": {"mean": {"psnr": extrap}}}, "freeze_baseline": {"mean": {"psnr": frozen}},
        "motion": {"velocity": {"observed": {"relative_l2": vel_obs}, "future": {"relative_l2": vel_fut}}}}))
    rows = [{"iteration": i, "elapsed_s": elapsed * i / iterations} for i in (iterations // 2, iterations)]
    (folder / "log.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    if probe is not None:
        (folder / "motion_form.json").write_text(json.dumps({"probe_s": probe}))


@pytest.fixture()
def study(tmp_path):
    """Two scenes, each with its default run and a half-budget one, and a third scene whose default
    run has not finished (left out), plus a run of another ablation (not read)."""
    write_run(tmp_path / "random-1-full-s0", 3000, 90.0, 10.0, 0.4, 0.8, 30.0, 28.0)
    write_run(tmp_path / "random-1-full-s0-train.iterations=1500", 1500, 40.0, 10.0, 0.6, 1.0, 29.0, 28.0)
    write_run(tmp_path / "random-2-full-s0", 9000, 300.0, None, 0.2, 0.3, 25.0, 20.0)
    write_run(tmp_path / "random-2-full-s0-train.iterations=4500", 4500, 180.0, None, 0.3, 0.5, 22.0, 20.0)
    write_run(tmp_path / "random-3-full-s0-train.iterations=1500", 1500, 40.0, 10.0, 0.6, 1.0, 29.0, 28.0)
    write_run(tmp_path / "random-1-deform-only-s0", 3000, 50.0, None, None, None, 27.0, 28.0)
    return tmp_path


def test_pareto_reads_each_budget_against_its_scene_default(study, tmp_path):
    records = {(r["scene"], r["iterations"]): r for r in family_budget.collect(study)}
    assert set(records) == {("random-1", 3000), ("random-1", 1500), ("random-2", 9000), ("random-2", 4500)}
    half = records[("random-1", 1500)]
    assert half["fraction"] == 0.5
    assert half["cost_s"] == 50.0  # 40 s of training + the 10 s probe
    assert half["cost_ratio"] == pytest.approx(50.0 / 100.0)
    assert half["gain_frozen"] == pytest.approx(1.0)
    assert records[("random-2", 4500)]["cost_ratio"] == pytest.approx(180.0 / 300.0)

    (low, n_low, half_stats), (one, n_one, default_stats) = family_budget.summary(family_budget.collect(study))
    assert (low, n_low, one, n_one) == (0.5, 2, 1.0, 2)
    assert half_stats["cost_ratio"][0] == pytest.approx(0.55)  # median of 0.5 and 0.6
    assert half_stats["vel_obs"][0] == pytest.approx(0.45)
    assert half_stats["vel_obs"][1:] == pytest.approx((0.33, 0.57))  # 10th and 90th percentiles of 0.3, 0.6
    assert half_stats["gain_frozen"][0] == pytest.approx(1.5)  # +1 and +2 dB
    assert default_stats["cost_ratio"] == (1.0, 1.0, 1.0)
    assert default_stats["gain_frozen"][0] == pytest.approx(3.5)  # +2 and +5 dB


def test_pareto_command_writes_the_table_and_the_plot(study, tmp_path):
    plot, table = tmp_path / "out" / "pareto.png", tmp_path / "out" / "pareto.md"
    output = bench_family("pareto", "--out", study, "--plot", plot, "--write", table).output
    lines = output.splitlines()
    assert lines[0].startswith("| budget (× default iterations) | scenes | cost (× default run) |")
    assert lines[2].startswith("| 0.5 | 2 | 0.55 (0.51–0.59) | 115 (63–167) | 0.450 (0.330–0.570) |")  # 50 and 180 s
    assert lines[3].startswith("| 1 | 2 | 1.00 (1.00–1.00) |")
    assert table.read_text() == output
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pareto_without_default_runs_names_the_folder(tmp_path):
    write_run(tmp_path / "random-3-full-s0-train.iterations=1500", 1500, 40.0, 10.0, 0.6, 1.0, 29.0, 28.0)
    result = bench_family("pareto", "--out", tmp_path, code=2)
    assert "--out" in result.output and str(tmp_path) in result.output


def test_budgets_grid_trains_each_default_and_its_shares(tmp_path):
    """Tuning seed 5 is filmed by a hemisphere of cameras and seed 10 by one moving camera, so their
    defaults resolve to 3000 and 3 × 3000 iterations (spec/density.md, "The iteration budget")."""
    for seed in (5, 10):  # tiny renders of the drawn scenes: the rig, not the pixels, sets the budget
        make_random_scene(seed, tmp_path / "data" / f"random-{seed}", resolution=8, n_frames=4, n_points=20,
                          supersample=1)
    output = bench_family("budgets", "--seeds", "5,10", "--fractions", "0.25,0.5", "--out", tmp_path).output
    assert f"velogauss sweep {tmp_path / 'grid.toml'}" in output
    sweep = load_grid(tmp_path / "grid.toml")
    names = sorted(p.name for p in sweep.points)
    assert names == sorted(["random-5-full-s0", "random-5-full-s0-train.iterations=750",
                            "random-5-full-s0-train.iterations=1500", "random-10-full-s0",
                            "random-10-full-s0-train.iterations=2250", "random-10-full-s0-train.iterations=4500"])
    defaults = [p for p in sweep.points if "=" not in p.name]
    assert all(sweep.out / p.name == family.run_folder(tmp_path, p.name.removesuffix("-full-s0"), "full")
               for p in defaults)
    assert all(p.threads == 1 and p.ablation == "full" and p.seed == 0 for p in sweep.points)


@pytest.mark.parametrize("fractions", ["0.5,1", "0", "half", ""])
def test_budgets_bad_fractions_render_nothing(tmp_path, monkeypatch, fractions):
    monkeypatch.setattr(family, "make_random_scene", lambda *a: pytest.fail("rendered despite bad input"))
    result = bench_family("budgets", "--seeds", "5", "--fractions", fractions, "--out", tmp_path, code=2)
    assert "--fractions" in result.output
    assert not (tmp_path / "grid.toml").exists()
