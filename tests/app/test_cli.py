"""Tests of velogauss/cli.py and the run-folder helpers it calls (velogauss/run.py): every
subcommand's help, the scene list, and bad input (exit code 2 and one line naming the thing).
The train → eval → render → export path is run in tests/app/test_end_to_end.py."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.run import default_run_dir, motion_form_line, parse_background, train_flags
from velogauss.scenes import SCENES
from tests.app.cli_checks import assert_refused

runner = CliRunner()
COMMANDS = ["make-scene", "train", "eval", "render", "export", "view", "sweep", "walkthrough", "bench", "diagnose"]
BENCHMARKS = ["raster", "motion", "accuracy", "effects", "export", "viewer", "load", "step_profile", "gpu_step",
              "step_ratio", "fidelity", "futures"]
DIAGNOSTICS = ["centre", "visibility"]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_top_level_help_lists_every_command():
    result = invoke("--help")
    assert result.exit_code == 0
    for command in COMMANDS:
        assert command in result.output


@pytest.mark.parametrize("command", COMMANDS + [f"bench {b}" for b in BENCHMARKS]
                         + [f"diagnose {d}" for d in DIAGNOSTICS])
def test_subcommand_help(command):
    result = invoke(*command.split(), "--help")
    assert result.exit_code == 0, result.output
    assert "Usage:" in result.output


@pytest.mark.parametrize("group, names", [("bench", BENCHMARKS), ("diagnose", DIAGNOSTICS)])
def test_group_help_lists_every_command(group, names):
    result = invoke(group, "--help")
    assert result.exit_code == 0, result.output
    for name in names:
        assert name in result.output


def test_make_scene_list_shows_every_scene_and_its_effects():
    result = invoke("make-scene", "--list")
    assert result.exit_code == 0
    lines = result.output.strip().splitlines()
    assert len(lines) == len(SCENES)
    for line, (name, build) in zip(lines, SCENES.items()):
        assert line.startswith(name)
        assert ", ".join(build().effects) in line
    assert "(default)" in result.output


def test_make_scene_unknown_name(tmp_path):
    assert_refused(invoke("make-scene", "volcano", "--out", tmp_path / "s"), "volcano")


def test_make_scene_without_name():
    assert_refused(invoke("make-scene"), "NAME")


def test_eval_missing_run_dir(tmp_path):
    missing = tmp_path / "no-such-run"
    assert_refused(invoke("eval", missing), missing)


def test_render_run_dir_without_checkpoint(tmp_path):
    (tmp_path / "run").mkdir()
    assert_refused(invoke("render", tmp_path / "run"), Path("checkpoints") / "latest.pt")


@pytest.mark.parametrize("time", ["nan", "inf", "soon"])
def test_export_bad_time(tmp_path, time):
    assert_refused(invoke("export", tmp_path, "--time", time), "--time:", time)


def test_eval_bad_split(tmp_path):
    assert_refused(invoke("eval", tmp_path, "--split", "future"), "--split", "future")


def test_train_bad_background(tmp_path):
    assert_refused(invoke("train", "--out", tmp_path / "run", "--background", "1,0"), "--background", "1,0")


def test_train_bad_effect(tmp_path):
    assert_refused(invoke("train", "--out", tmp_path / "run", "--effects", "rotation,magic"), "--effects", "magic")


def test_train_missing_data_dir(tmp_path):
    missing = tmp_path / "nowhere"
    assert_refused(invoke("train", missing, "--out", tmp_path / "run"), missing)


def test_train_missing_config_file(tmp_path):
    missing = tmp_path / "cfg.toml"
    assert_refused(invoke("train", "--out", tmp_path / "run", "--config", missing), missing)


def test_bench_unknown_benchmark():
    result = invoke("bench", "disk")
    assert result.exit_code == 2 and "No such command" in result.output and "disk" in result.output, result.output
    assert "Traceback" not in result.output


def test_bench_bad_list_names_the_option(tmp_path):
    assert_refused(invoke("bench", "load", "--settings", "fast", "--out", tmp_path / "R.md"), "settings", "fast")
    assert_refused(invoke("bench", "raster", "--workloads", ",", "--out", tmp_path / "R.md"), "--workloads")
    assert_refused(invoke("bench", "step_profile", "--sizes", "400,8OO", "--gaussians", "20000", "--out",
                          tmp_path / "R.md"), "--sizes", "8OO")
    assert_refused(invoke("bench", "step_profile", "--sizes", "400", "--gaussians", "8", "--out", tmp_path / "R.md"),
                   "--gaussians", "[8]")
    assert not (tmp_path / "R.md").exists()


def test_bench_on_a_device_it_does_not_measure(tmp_path):
    assert_refused(invoke("bench", "step_profile", "--device", "cuda", "--out", tmp_path / "R.md"), "--device",
                     "cuda")


def test_diagnose_missing_run(tmp_path):
    missing = tmp_path / "no-such-run"
    assert_refused(invoke("diagnose", "centre", missing), missing)
    assert_refused(invoke("diagnose", "centre", missing, "--times", "0,soon"), "--times", "soon")


def test_flags_become_typed_config_values():
    flags = train_flags(effects="translation, rotation", max_time=0.5, half_res=True, background="black")
    assert flags == {"model.effects": ("--effects", ["translation", "rotation"]), "data.max_time": ("--max-time", 0.5),
                     "data.half_res": ("--half-res", True), "data.background": ("--background", (0.0, 0.0, 0.0))}


def test_bad_flag_values_name_the_flag(tmp_path):
    assert_refused(invoke("train", "--out", tmp_path / "run", "--effects", "translation,magic"), "--effects",
                     "model.effects", "magic")
    assert_refused(invoke("train", "--out", tmp_path / "run", "--iterations", 0), "--iterations",
                     "train.iterations")
    assert not (tmp_path / "run").exists()


def test_background_parsing():
    assert parse_background("white") == (1.0, 1.0, 1.0)
    assert parse_background("0.1,0.2,0.3") == (0.1, 0.2, 0.3)
    with pytest.raises(ValueError, match="^--background: "):
        parse_background("2,0,0")


def test_default_run_dir_names_scene_and_time():
    import datetime

    path = default_run_dir("toss", now=datetime.datetime(2025, 3, 4, 5, 6, 7))
    assert path == Path("runs") / "toss-20250304-050607"


def test_the_command_says_what_was_chosen_and_whether_the_future_holds(tmp_path):
    assert motion_form_line(tmp_path) is None  # a run whose form was set chose nothing
    report = {"choice": "mlp", "scores": {"rigid": [1.5, 1.2, 1.1], "mlp": [1.32, 0.99, 0.84]}, "future": "hold"}
    (tmp_path / "motion_form.json").write_text(json.dumps(report))
    assert motion_form_line(tmp_path) == ("motion form: mlp (tail scores 1.32 / 0.99 / 0.84; 1 = freezing); the future "
                                          "holds: no form predicted the held-out tails better than freezing the motion")
    report.update(choice="rigid", scores={"rigid": [0.3, 0.29, 0.27]}, future="integrate")
    (tmp_path / "motion_form.json").write_text(json.dumps(report))
    assert motion_form_line(tmp_path) == ("motion form: rigid (tail scores 0.30 / 0.29 / 0.27; 1 = freezing); the "
                                          "motion is integrated past the window")
    report.update(choice="mlp", scores={"mlp": [0.6, 0.7, 0.8]}, future="coast")  # a future the user set
    (tmp_path / "motion_form.json").write_text(json.dumps(report))
    assert motion_form_line(tmp_path) == ("motion form: mlp (tail scores 0.60 / 0.70 / 0.80; 1 = freezing); the "
                                          "motion coasts past the window: its patterns keep their value at the "
                                          "window's end")
    report.update(choice="harmonic", patterns="harmonic", scores={"harmonic": [0.4, 0.5, 0.45]}, future="integrate",
                  first_scores={"mlp": [0.6, 0.7, 0.8]}, first_choice="rigid-drift",
                  window_psnr={"mlp": 19.1, "rigid-drift": 18.0, "harmonic": 33.25, "probe_s": 60.0})
    (tmp_path / "motion_form.json").write_text(json.dumps(report))
    assert motion_form_line(tmp_path) == ("motion form: harmonic (tail scores 0.40 / 0.50 / 0.45; 1 = freezing); the "
                                          "first probe's paths chose rigid-drift, but a probe with the oscillators "
                                          "reconstructs the window at 33.25 dB against the time network's 19.10, and "
                                          "the scores are of the oscillators' own paths; the motion is integrated past "
                                          "the window")
    (tmp_path / "motion_form.json").write_text(json.dumps({"choice": "mlp", "scores": {}, "future": "integrate",
                                                           "reason": "the observed window reaches t = 1"}))
    assert motion_form_line(tmp_path) == "motion form: mlp (the observed window reaches t = 1)"
