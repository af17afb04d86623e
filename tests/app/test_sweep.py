"""Tests of velogauss/sweep: the grid file, the resume plan, the report, and real sweeps on
local Ray (two tiny points plus two failing ones; a sweep killed with SIGKILL and resumed)."""

import csv
import dataclasses
import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.config import load_config, to_toml
from velogauss.sweep.grid import load_grid
from velogauss.sweep.report import METRICS, write_report
from velogauss.sweep.runner import plan_point, point_config

ROOT = Path(__file__).resolve().parents[2]
needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                               reason="Ray is not installed (pip install 'velogauss[sweep]')")

# A 24-pixel, 4-view, 6-time scene and 12 iterations of a small model: a few seconds a run.
TINY_GRID = """
threads = 1
[set]
"train.iterations" = 12
"train.warmup" = 3
"train.curriculum" = 4
"train.eval_every" = 6
"train.checkpoint_every" = 4
"densify.start" = 2
"densify.every" = 4
"densify.until" = 10
"physics.n_points" = 64
"physics.ramp" = 2
"model.hidden" = 16
"model.depth" = 1
"model.n_patterns" = 4
"model.code_dim" = 4
# The scenes' declared effects and rigid patterns (toss and spin are rigid), what "auto" resolved to
# when it read scene.json: not about the motion form, and "auto" would first train a backtest probe.
"model.effects" = "declared"
"model.patterns" = "rigid"
[scene_options]
resolution = 24
n_views = 4
n_times = 6
n_points = 300
n_heldout = 1
"""


def _grid(tmp_path, body, name="grid.toml"):
    path = tmp_path / name
    path.write_text(body)
    return path


def test_grid_takes_the_product_of_its_lists(tmp_path):
    path = _grid(tmp_path, """
out = "sweep"
[set]
"train.iterations" = 50
[[grid]]
scenes = ["toss", "spin"]
data = ["folder/lego"]
ablations = ["full", "no-adf"]
seeds = [0, 1]
[grid.set]
"model.integrator" = ["rk2", "rk4"]
[[grid]]
scenes = ["toss"]
ablations = ["full"]
[grid.set]
"model.integrator" = ["rk2"]
[[grid]]
scenes = ["grow"]
threads = 2
""")
    sweep = load_grid(path)
    # 3 sources x 2 ablations x 2 seeds x 2 integrators; the second grid only repeats a point
    # (equal points merge), the third adds one with its own thread count.
    assert len(sweep.points) == 25 and sweep.out == Path("sweep") and sweep.threads == 1
    names = [p.name for p in sweep.points]
    assert names[0] == "toss-full-s0-model.integrator=rk2" and len(set(names)) == 25
    assert [p.threads for p in sweep.points] == [1] * 24 + [2]
    lego = [p for p in sweep.points if p.scene is None]
    assert len(lego) == 8 and {p.data for p in lego} == {str((tmp_path / "folder/lego").resolve())}
    point = next(p for p in sweep.points if p.name == "spin-no-adf-s1-model.integrator=rk4")
    assert point.group == "spin-no-adf-model.integrator=rk4"
    assert point.overrides == ("train.iterations=50", 'model.integrator="rk4"')
    assert point.settings == (("model.integrator", "rk4"),)


@pytest.mark.parametrize("body, named", [
    ("[[grid]]\nscenes = ['volcano']", "volcano"),
    ("[[grid]]\nscenes = ['toss']\nseeds = []", "seeds"),
    ("[[grid]]\nscenes = ['toss']\nablations = 'full'", "ablations"),
    ("[[grid]]\nscenes = ['toss']\ncolour = 1", "colour"),
    ("[[grid]]\nablations = ['full']", "scenes"),
    ("threads = 0\n[[grid]]\nscenes = ['toss']", "threads"),
    ("[[grid]]\nscenes = ['toss']\nthreads = 1.5", "grid\\[0\\].threads"),
    ("[[grid]]\nscenes = ['toss']\n[grid.set]\n'model.step' = 0.1", "model.step"),
    ("out = 'x'", "grid"),
    ("[[grid]\n", "not valid TOML"),
])
def test_bad_grid_files_name_the_key(tmp_path, body, named):
    path = _grid(tmp_path, body)
    with pytest.raises(ValueError, match=named) as err:
        load_grid(path)
    assert str(path) in str(err.value)


def test_cli_bad_grid_is_one_error_line(tmp_path):
    result = CliRunner().invoke(app, ["sweep", str(tmp_path / "missing.toml")])
    assert result.exit_code == 2 and "missing.toml" in result.output and "Traceback" not in result.output
    result = CliRunner().invoke(app, ["sweep", str(_grid(tmp_path, "[[grid]]\nscenes = ['toss']"))])
    assert result.exit_code == 2 and "out" in result.output


def _as_a_run_writes(cfg):
    """`cfg` with train.iterations a number, as a run's config.toml holds it (the toss, filmed by
    more cameras than train.views at every time, resolves "auto" to 3,000)."""
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, iterations=3000))


def test_resume_plan_skips_done_points_and_never_overwrites_another_config(tmp_path):
    sweep = load_grid(_grid(tmp_path, "[[grid]]\nscenes = ['toss']\nseeds = [0, 1]"))
    first, second = sweep.points
    assert plan_point(first, None, tmp_path).action == "train"
    run = tmp_path / first.name
    run.mkdir()
    cfg = _as_a_run_writes(point_config(first, None, tmp_path / "data" / "toss"))
    (run / "config.toml").write_text(to_toml(cfg))
    assert plan_point(first, None, tmp_path).action == "train"  # killed before its first checkpoint
    (run / "checkpoints").mkdir()
    (run / "checkpoints" / "latest.pt").write_bytes(b"")
    assert plan_point(first, None, tmp_path).action == "resume"
    (run / "metrics.json").write_text("{}")
    assert plan_point(first, None, tmp_path).action == "skip"
    # The second point's folder holds the first point's config (seed 0, not 1): left alone.
    (tmp_path / second.name).mkdir()
    (tmp_path / second.name / "config.toml").write_text(to_toml(cfg))
    plan = plan_point(second, None, tmp_path)
    assert plan.action == "fail" and "different config" in plan.error
    assert load_config(tmp_path / second.name / "config.toml") == cfg


def test_a_finished_point_on_a_scene_with_its_own_window_and_background_is_skipped(tmp_path):
    """A generated scene's own max_time and background (scene.json) go into the run's config.toml
    where the grid left the defaults; planning the same grid again must skip the finished point,
    and a grid that sets another max_time must still be refused."""
    sweep = load_grid(_grid(tmp_path, "[[grid]]\nscenes = ['toss']"))
    (point,) = sweep.points
    cfg = _as_a_run_writes(point_config(point, None, tmp_path / "data" / "toss"))
    own = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, max_time=0.7368, background=(0.0, 0.0, 0.0)))
    run = tmp_path / point.name
    run.mkdir()
    (run / "config.toml").write_text(to_toml(own))
    (run / "metrics.json").write_text("{}")
    assert plan_point(point, None, tmp_path).action == "skip"
    other = load_grid(_grid(tmp_path, "[[grid]]\nscenes = ['toss']\n[grid.set]\n'data.max_time' = [0.5]"))
    (set_point,) = other.points
    (tmp_path / set_point.name).mkdir()
    (tmp_path / set_point.name / "config.toml").write_text(to_toml(own))
    (tmp_path / set_point.name / "metrics.json").write_text("{}")
    assert plan_point(set_point, None, tmp_path).action == "fail"


def test_a_finished_point_with_the_default_form_is_skipped(tmp_path):
    """A point left at the default "auto" motion form: its run's config.toml holds what the
    backtest chose (velogauss.train.backtest: patterns, mixing start, maybe effects without
    gravity); planning the same grid again must see the same config and skip it."""
    sweep = load_grid(_grid(tmp_path, "[[grid]]\nscenes = ['toss']"))
    (point,) = sweep.points
    cfg = _as_a_run_writes(point_config(point, None, tmp_path / "data" / "toss"))
    assert cfg.model.patterns == "auto"
    chosen = dataclasses.replace(cfg, model=dataclasses.replace(
        cfg.model, patterns="rigid", mixing_init="uniform", effects=("translation", "rotation", "static")))
    run = tmp_path / point.name
    run.mkdir()
    (run / "config.toml").write_text(to_toml(chosen))
    (run / "metrics.json").write_text("{}")
    plan = plan_point(point, None, tmp_path)
    assert (plan.action, plan.error) == ("skip", "")


def test_report_mean_and_spread_over_seeds(tmp_path):
    sweep = load_grid(_grid(tmp_path, "[[grid]]\nscenes = ['toss']\nseeds = [0, 1, 2]\n"
                                      "[[grid]]\nscenes = ['spin']"))
    psnr = {0: 20.0, 1: 21.0, 2: 25.0}
    outcomes = {p.name: {"status": "ok", "metrics": {"interp_psnr": psnr[p.seed], "train_min": 1.0,
                                                     "code": "abcdef0"}}
                for p in sweep.points[:3]}
    outcomes[sweep.points[3].name] = {"status": "failed", "error": "DataError: broken | file"}
    written = write_report(tmp_path, sweep.points, outcomes)
    table = (tmp_path / "results.md").read_text()
    # mean 22, sample standard deviation sqrt(((-2)^2 + (-1)^2 + 3^2) / 2) = sqrt(7) = 2.65.
    assert "| toss-full | 3 | 22.00 ± 2.65 |" in table
    assert "| spin-full-s0 | DataError: broken / file |" in table
    rows = list(csv.DictReader((tmp_path / "results.csv").open()))
    assert [r["status"] for r in rows] == ["ok", "ok", "ok", "failed"]
    assert float(rows[2]["interp_psnr"]) == 25.0 and rows[3]["interp_psnr"] == ""
    assert [r["code"] for r in rows] == ["abcdef0"] * 3 + [""]
    assert {p.name for p in written if p.parent.name == "plots"} == {"interp_psnr.png", "train_min.png"}
    assert len(METRICS) == len(set(m for m, _, _ in METRICS))


def _sweep(grid, out, *args, **popen):
    # Ray's memory monitor kills the newest task when the machine is nearly full; another test
    # running beside these (pytest -n 2) may briefly fill it, which says nothing about the sweep.
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
           "RAY_AUTH_MODE": "disabled", "RAY_memory_monitor_refresh_ms": "0"}
    command = [sys.executable, "-m", "velogauss", "sweep", str(grid), "--out", str(out), *args]
    return subprocess.Popen(command, env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, **popen)


@pytest.mark.slow
@needs_ray
def test_two_point_grid_on_local_ray_records_failures_and_goes_on(tmp_path):
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "transforms_train.json").write_text("{ not json")
    grid = _grid(tmp_path, TINY_GRID + """
[[grid]]
scenes = ["toss"]
ablations = ["full", "no-adf"]
[[grid]]
data = ["broken"]
[[grid]]
scenes = ["spin"]
[grid.set]
"model.integrator" = ["bogus"]
""")
    proc = _sweep(grid, tmp_path / "out", "--cpus", "2")
    output, _ = proc.communicate(timeout=300)
    assert proc.returncode == 1, output  # some runs failed
    rows = {r["run"]: r for r in csv.DictReader((tmp_path / "out" / "results.csv").open())}
    assert {n: r["status"] for n, r in rows.items()} == {
        "toss-full-s0": "ok", "toss-no-adf-s0": "ok", "broken-full-s0": "failed",
        "spin-full-s0-model.integrator=bogus": "failed"}
    assert "transforms_train.json" in rows["broken-full-s0"]["error"]
    assert "bogus" in rows["spin-full-s0-model.integrator=bogus"]["error"]
    for name in ("toss-full-s0", "toss-no-adf-s0"):
        assert np.isfinite(float(rows[name]["extrap_psnr"])) and float(rows[name]["train_min"]) > 0
        # A torch process's own peak resident memory: above the interpreter's, far below the machine's.
        assert 0.1 < float(rows[name]["train_peak_gb"]) < 8
        assert load_config(tmp_path / "out" / name / "config.toml").train.iterations == 12
        if (ROOT / ".git").exists():  # the checkout these tests run from trained it
            head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
            assert rows[name]["code"].rstrip("+") == head.stdout.strip()[:7]
    assert (tmp_path / "out" / "plots" / "extrap_psnr.png").stat().st_size > 0
    assert "| toss-no-adf | 1 |" in (tmp_path / "out" / "results.md").read_text()


@pytest.mark.slow
@needs_ray
def test_killed_sweep_resumes_without_redoing_finished_points(tmp_path):
    grid = _grid(tmp_path, TINY_GRID + '[[grid]]\nscenes = ["toss"]\nseeds = [0, 1]\n')
    out = tmp_path / "out"
    # One CPU: the points run one after the other; kill the whole sweep (driver and Ray) once
    # the first has finished.
    proc = _sweep(grid, out, "--cpus", "1", start_new_session=True)
    deadline = time.monotonic() + 240
    try:
        while not list(out.glob("*/metrics.json")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
    done = list(out.glob("*/metrics.json"))
    assert len(done) == 1, "the sweep was not killed between its two points"
    finished = done[0]
    stamp = finished.stat().st_mtime_ns
    proc = _sweep(grid, out, "--cpus", "1")
    output, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, output
    assert f"skip    {finished.parent.name}" in output
    assert finished.stat().st_mtime_ns == stamp
    rows = {r["run"]: r["status"] for r in csv.DictReader((out / "results.csv").open())}
    assert rows.pop(finished.parent.name) == "skipped"
    # The other point: trained by the resumed sweep, or (when the kill found its Ray worker
    # mid-run and the worker finished it on its own) skipped as done as well.
    assert list(rows.values()) in (["ok"], ["skipped"])
    assert all((out / run / "metrics.json").is_file() for run in [finished.parent.name, *rows])


def test_the_readme_grid_is_the_ten_default_runs(tmp_path):
    """benchmarks/grids/scenes.toml trains what `velogauss train --scene S --ablation A` trains."""
    sweep = load_grid(ROOT / "benchmarks" / "grids" / "scenes.toml")
    names = {p.name for p in sweep.points}
    assert names == {f"{s}-full-s0" for s in ("toss", "spin", "multi", "stretch", "shear", "grow")} | {
        f"toss-{a}-s0" for a in ("no-pds", "no-adf", "no-gpc", "deform-only")}
    for point in sweep.points:
        cli_default = load_config(None, [f"model.ablation={point.ablation}"])
        assert point_config(point, sweep.config, tmp_path).train == cli_default.train
        assert point_config(point, sweep.config, tmp_path).model == cli_default.model
    assert sweep.threads == 1 and sweep.scene_options == {}


@pytest.mark.parametrize("name, split", [("dnerf_future", "future:0.8"), ("dnerf_standard", "all")])
def test_the_dnerf_grids_train_the_eight_scenes_at_400_px(tmp_path, name, split):
    sweep = load_grid(ROOT / "benchmarks" / "grids" / f"{name}.toml")
    scenes = ("bouncingballs", "hellwarrior", "hook", "jumpingjacks", "lego", "mutant", "standup", "trex")
    assert {p.name for p in sweep.points} == {f"{s}-{a}-s0" for s in scenes for a in ("full", "deform-only")}
    cfg = point_config(sweep.points[0], sweep.config, tmp_path)
    assert cfg.data.split == split and cfg.data.half_res and cfg.data.background == (0.0, 0.0, 0.0)
    assert cfg.train == load_config().train and cfg.model == load_config().model  # the defaults otherwise


def test_sweep_help():
    result = CliRunner().invoke(app, ["sweep", "--help"])
    assert result.exit_code == 0 and "--address" in result.output
