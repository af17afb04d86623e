"""What a user can do wrong, one test per case (issue 13): each asserts the exit code, a message
naming the file, key or limit, and that nothing the user already had changed (checkpoint bytes,
config, log). Every command runs in-process through the typer app on a 16-pixel scene and a
run of a few iterations, so the whole file takes well under a minute."""

import errno
import io
import json
import os
import shutil
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from typer.testing import CliRunner

from velogauss import io_utils
from velogauss.cli import app
from velogauss.train import loop
from velogauss.train.checkpoint import checkpoint_path, header
from velogauss_core.constants import SSIM_WINDOW, TIME_HORIZON
from tests.app.cli_checks import assert_refused

# Few iterations, a small model; eval and checkpoint every 2 so logs and checkpoints exist
# in the middle of a run.
ITERATIONS = 4
FAST = ["--set", "train.eval_every=1", "--set", "train.checkpoint_every=2", "--set", "train.warmup=1",
        "--set", "train.curriculum=2", "--set", "model.init_points=200", "--set", "physics.n_points=32",
        # The spin's declared effects and rigid patterns, what "auto" resolved to when it read
        # scene.json: these tests are not about the motion form, and an "auto" form would first
        # train the backtest's probe (velogauss.train.backtest).
        "--set", "model.effects=declared", "--set", "model.patterns=rigid"]


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def train(scene, out, *extra):
    return invoke("train", scene, "--out", out, "--no-eval", "--iterations", ITERATIONS, *FAST, *extra)


def snapshot(folder):
    """Every file under `folder` and its bytes."""
    folder = Path(folder)
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("scenes")
    result = invoke("make-scene", "spin", "--out", root / "base16", "--resolution", 16, "--views", 3, "--times", 5)
    assert result.exit_code == 0, result.output
    return root / "base16"


@pytest.fixture(scope="module")
def trained(scene, tmp_path_factory):
    """A finished run of ITERATIONS iterations (never modified: tests copy it)."""
    run = tmp_path_factory.mktemp("runs") / "done"
    result = train(scene, run)
    assert result.exit_code == 0, result.output
    return run


@pytest.fixture
def run(trained, tmp_path):
    """A copy of the finished run that a test may try to damage."""
    return Path(shutil.copytree(trained, tmp_path / "run"))


# --- 1. inference: no gradients, bounded time -------------------------------------------

@pytest.mark.parametrize("time", ["1e6", "-101", "nan", "inf"])
def test_export_refuses_a_time_past_the_horizon_or_not_finite(run, time):
    before = snapshot(run)
    result = invoke("export", run, "--time", time)
    names = ("--time", time) if time in ("nan", "inf") else ("--time", time, f"{TIME_HORIZON:g}")
    assert_refused(result, *names)
    assert snapshot(run) == before and not (run / "export").exists()


def test_export_keeps_no_autograd_graph(run):
    """No tensor is saved for a backward pass while export runs: memory does not grow with the
    number of integration steps. (eval and render kept none before issue 13 either.)"""
    saved = []
    with torch.autograd.graph.saved_tensors_hooks(lambda x: saved.append(x.shape) or x, lambda x: x):
        result = invoke("export", run, "--time", 3)
    assert result.exit_code == 0, result.output
    assert saved == []


def test_far_export_matches_the_unchunked_integration(run, tmp_path, monkeypatch):
    """Integrating in chunks of stage times (bounded memory) gives the Gaussians that one
    chunk of every stage gives."""
    from velogauss_fast.motion import trajectory

    assert invoke("export", run, "--time", 4, "--out", tmp_path / "chunked.ply").exit_code == 0
    monkeypatch.setattr(trajectory, "STAGE_CHUNK", 10**6)
    assert invoke("export", run, "--time", 4, "--out", tmp_path / "whole.ply").exit_code == 0
    a, b = (np.frombuffer((tmp_path / f).read_bytes()[-4000:], "<f4") for f in ("chunked.ply", "whole.ply"))
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


# --- 2. training into an existing run -----------------------------------------------------

@pytest.mark.parametrize("extra", [("--iterations", 2), ("--iterations", 8, "--set", "train.seed=3")])
def test_train_into_an_existing_run_is_refused(scene, run, extra):
    before = snapshot(run)
    result = invoke("train", scene, "--out", run, "--no-eval", *extra)
    assert_refused(result, str(run), "--resume", "--out", "--overwrite")
    assert snapshot(run) == before


def test_readme_continue_line_without_resume_is_refused(run):
    """The README's continue line with --resume forgotten (no scene: the default scene would
    be generated into RUN/data)."""
    before = snapshot(run)
    result = invoke("train", "--out", run, "--iterations", 5)
    assert_refused(result, "--resume", "--overwrite")
    assert snapshot(run) == before and not (run / "data").exists()


def test_overwrite_replaces_the_run(scene, run):
    (run / "metrics.json").write_text("{}")
    # An earlier run's backtest and forecast reports, which this run (its form set) does not write.
    (run / "motion_form.json").write_text('{"choice": "harmonic"}')
    (run / "forecast.json").write_text('{"choice": "rigid"}')
    old = checkpoint_path(run).read_bytes()
    result = train(scene, run, "--overwrite", "--set", "train.seed=1")
    assert result.exit_code == 0, result.output
    assert checkpoint_path(run).read_bytes() != old
    assert "seed = 1" in (run / "config.toml").read_text()
    # Neither the old run's metrics nor its reports describe the new one.
    assert not any((run / name).exists() for name in ("metrics.json", "motion_form.json", "forecast.json"))


# --- 3. resume with a changed config ------------------------------------------------------

@pytest.mark.parametrize("change, old, new", [("data.max_time=0.5", 0.75, 0.5),
                                              ("model.integrator=rk4", "rk2", "rk4"),
                                              ("model.hidden=16", 64, 16)])
def test_resume_with_a_changed_config_is_refused(run, change, old, new):
    before = snapshot(run)
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--set", change)
    assert_refused(result, change.split("=")[0], repr(old), repr(new), "train.iterations")
    assert snapshot(run) == before


def test_resume_may_change_the_iterations_and_config_follows(run):
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 2)
    assert result.exit_code == 0, result.output
    assert f"iterations = {ITERATIONS + 2}" in (run / "config.toml").read_text()
    payload = _payload(run)
    assert payload["iteration"] == ITERATIONS + 2 == payload["config"]["train"]["iterations"]


# --- 4. the file system -------------------------------------------------------------------

@pytest.mark.parametrize("command", ["train", "eval", "render", "export"])
def test_unwritable_output_is_reported_before_work(scene, run, tmp_path, command):
    """An output under a plain file cannot be created (any user, root included)."""
    blocker = tmp_path / "blocker"
    blocker.write_text("a file, not a folder")
    before = snapshot(run)
    args = {"train": ("train", scene, "--out", blocker / "run", "--no-eval", "--iterations", 2),
            "eval": ("eval", run),
            "render": ("render", run, "--out", blocker / "renders"),
            "export": ("export", run, "--time", 1, "--out", blocker / "x.ply")}[command]
    if command == "eval":  # the metrics file cannot be written over a folder of that name
        (run / "metrics.json").mkdir()
        before = snapshot(run)
        assert_refused(invoke(*args), run / "metrics.json")
        assert snapshot(run) == before and (run / "metrics.json").is_dir()
        return
    result = invoke(*args)
    assert_refused(result, "blocker")
    assert snapshot(run) == before and blocker.read_text() == "a file, not a folder"


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_run_folder_is_reported_before_eval(run):
    before = snapshot(run)
    run.chmod(0o555)
    try:
        result = invoke("eval", run)
    finally:
        run.chmod(0o755)
    assert_refused(result, str(run), "not writable")
    assert snapshot(run) == before


def test_full_disk_is_reported_naming_the_path_and_keeps_the_checkpoint(run, monkeypatch):
    before = checkpoint_path(run).read_bytes()
    fsync = io_utils._fsync

    def full_disk(path):
        if path.name.startswith(".latest.pt."):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        fsync(path)

    monkeypatch.setattr(io_utils, "_fsync", full_disk)
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 2)
    assert_refused(result, "no space left on device", checkpoint_path(run))
    assert checkpoint_path(run).read_bytes() == before
    assert [p.name for p in checkpoint_path(run).parent.iterdir()] == ["latest.pt"]


# --- 5. devices -----------------------------------------------------------------------------

@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
@pytest.mark.parametrize("command", ["train", "eval", "render", "export"])
def test_missing_device_is_named_at_the_door(scene, run, tmp_path, command):
    before = snapshot(run)
    args = {"train": ("train", scene, "--out", tmp_path / "new", "--no-eval", "--iterations", 2), "eval": ("eval", run),
            "render": ("render", run), "export": ("export", run, "--time", 1)}[command]
    result = invoke(*args, "--device", "cuda")
    assert_refused(result, "cuda", "available: cpu")
    assert "unreadable" not in result.output
    assert snapshot(run) == before and not (tmp_path / "new").exists()


# --- 6. a torn log ----------------------------------------------------------------------------

def test_resume_tolerates_a_torn_last_log_line(run):
    log = run / "log.jsonl"
    whole = log.read_text()
    log.write_text(whole + '{"iteration": 5, "loss": 0.1')  # a crash in the middle of an append
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 1)
    assert result.exit_code == 0, result.output
    lines = log.read_text().splitlines()
    assert "\n".join(lines[:ITERATIONS]) + "\n" == whole
    assert [json.loads(line)["iteration"] for line in lines] == list(range(1, ITERATIONS + 2))


def test_a_broken_middle_log_line_names_the_file_and_line(run):
    log = run / "log.jsonl"
    lines = log.read_text().splitlines()
    lines[1] = lines[1][:10]
    log.write_text("\n".join(lines) + "\n")
    before = snapshot(run)
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 1)
    assert_refused(result, log, "line 2")
    assert snapshot(run) == before


# --- 7. images smaller than the SSIM window; no half-made run folder ----------------------

def test_images_smaller_than_the_ssim_window_are_rejected_at_load(tmp_path):
    small = tmp_path / "small"
    assert invoke("make-scene", "spin", "--out", small, "--resolution", SSIM_WINDOW - 1, "--views", 3,
                  "--times", 5).exit_code == 0
    before = snapshot(small)
    result = invoke("train", small, "--out", tmp_path / "run", "--no-eval", "--iterations", 2)
    assert_refused(result, "SSIM", f"{SSIM_WINDOW - 1}x{SSIM_WINDOW - 1}", small)
    assert not (tmp_path / "run").exists() and snapshot(small) == before


def test_failure_before_the_first_checkpoint_leaves_no_run_folder(scene, tmp_path, monkeypatch):
    def broken_step(self, it):
        raise RuntimeError("a bug in the first iteration")

    monkeypatch.setattr(loop.Trainer, "step", broken_step)
    result = train(scene, tmp_path / "run")
    assert isinstance(result.exception, RuntimeError)  # a bug keeps its traceback
    assert not (tmp_path / "run").exists()


# --- 8. config ranges ---------------------------------------------------------------------------

@pytest.mark.parametrize("setting", ["train.seed=-1", "train.lr_means=-1", "physics.bounds_margin=-5",
                                     "physics.lambda_transport=-1e3", "train.lr_opacity=-1",
                                     "densify.grad_threshold=-1", "densify.prune_opacity=2", "densify.until=-5",
                                     "densify.static_every=-1", "densify.opacity_reset_every=-1", "physics.ramp=-1"])
def test_out_of_range_config_values_name_the_key(scene, tmp_path, setting):
    result = invoke("train", scene, "--out", tmp_path / "run", "--no-eval", "--iterations", 2, "--set", setting)
    assert_refused(result, "--set", setting.split("=")[0], "got")
    assert not (tmp_path / "run").exists()


def test_out_of_range_value_in_a_config_file_names_file_and_key(scene, tmp_path):
    config = tmp_path / "my.toml"
    config.write_text("[densify]\nprune_opacity = 2.0\n")
    result = invoke("train", scene, "--out", tmp_path / "run", "--no-eval", "--iterations", 2, "--config", config)
    assert_refused(result, config, "densify.prune_opacity")
    assert config.read_text() == "[densify]\nprune_opacity = 2.0\n" and not (tmp_path / "run").exists()


# --- 9. checkpoint integrity ----------------------------------------------------------------

def _payload(run):
    data = checkpoint_path(run).read_bytes().partition(b"\n")[2]
    return torch.load(io.BytesIO(data), weights_only=False)


def _write_payload(run, payload):
    """A well-formed checkpoint (valid checksum) around `payload`, as a tool that edits checkpoints writes it."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    data = buffer.getvalue()
    checkpoint_path(run).write_bytes(header(data) + data)


def test_flipped_checkpoint_bytes_are_caught(run):
    data = bytearray(checkpoint_path(run).read_bytes())
    data[len(data) // 2] ^= 0xFF
    checkpoint_path(run).write_bytes(bytes(data))
    before = snapshot(run)
    result = invoke("eval", run)
    assert_refused(result, checkpoint_path(run), "checksum")
    assert snapshot(run) == before and not (run / "metrics.json").exists()


def test_checkpoint_missing_a_key_is_named(run):
    payload = _payload(run)
    del payload["optimizer"]
    _write_payload(run, payload)
    before = snapshot(run)
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 1)
    assert_refused(result, checkpoint_path(run), "optimizer", "missing")
    assert snapshot(run) == before


def test_checkpoint_with_nan_weights_is_named(run):
    payload = _payload(run)
    name = next(k for k, v in payload["model"].items() if v.is_floating_point())
    payload["model"][name].view(-1)[0] = float("nan")
    _write_payload(run, payload)
    before = snapshot(run)
    result = invoke("export", run, "--time", 1)
    assert_refused(result, checkpoint_path(run), f"model.{name}", "non-finite")
    assert snapshot(run) == before


# --- 10-12. stale temporaries, Ctrl-C, the log after a resume ----------------------------------

def test_stale_checkpoint_temporaries_are_removed_on_the_next_start(run):
    stale = checkpoint_path(run).parent / ".latest.pt.k1ll3d.tmp.pt"
    stale.write_bytes(b"half a checkpoint from a SIGKILL")
    result = invoke("train", "--out", run, "--resume", "--no-eval", "--iterations", ITERATIONS + 1)
    assert result.exit_code == 0, result.output
    assert [p.name for p in checkpoint_path(run).parent.iterdir()] == ["latest.pt"]


def test_ctrl_c_prints_the_checkpoint_and_resume_logs_as_an_uninterrupted_run(scene, trained, tmp_path,
                                                                               monkeypatch):
    step = loop.Trainer.step

    def step_then_interrupt(self, it):
        out = step(self, it)
        if it == 2:  # after the checkpoint at 2, before the one at 4
            signal.raise_signal(signal.SIGINT)
        return out

    monkeypatch.setattr(loop.Trainer, "step", step_then_interrupt)
    cut = tmp_path / "cut"
    result = train(scene, cut)
    assert result.exit_code == 130, result.output
    assert f"training interrupted; checkpoint at iteration 3 in {cut}" in result.output
    monkeypatch.setattr(loop.Trainer, "step", step)
    assert invoke("train", "--out", cut, "--resume", "--no-eval").exit_code == 0

    def records(run):
        # Wall time and peak memory are measurements of the process, not of the training's numbers.
        return [{k: v for k, v in json.loads(line).items() if k not in ("elapsed_s", "peak_rss_mib")}
                for line in (run / "log.jsonl").read_text().splitlines()]

    assert records(cut) == records(trained)


# --- also: 1-bit PNGs, --max-time nan, a zero velocity field ------------------------------------

def test_one_bit_pngs_are_read(scene, tmp_path):
    bits = Path(shutil.copytree(scene, tmp_path / "bits"))
    for png in bits.rglob("*.png"):
        Image.open(png).convert("L").point(lambda v: 255 if v > 128 else 0).convert("1").save(png)
    assert Image.open(next(bits.rglob("*.png"))).mode == "1"
    before = snapshot(bits)
    result = invoke("train", bits, "--out", tmp_path / "run", "--no-eval", "--iterations", 1)
    assert result.exit_code == 0, result.output
    assert snapshot(bits) == before


def test_max_time_nan_names_the_flag(scene, tmp_path):
    result = invoke("train", scene, "--out", tmp_path / "run", "--no-eval", "--iterations", 2, "--max-time", "nan")
    assert_refused(result, "--max-time", "nan")
    assert not (tmp_path / "run").exists()


def test_render_of_a_zero_velocity_field_warns_nothing(scene, tmp_path):
    """After one warm-up iteration the motion has not moved from its initialisation, whose
    velocity is exactly zero: the field figure draws zero-length arrows."""
    run = tmp_path / "run"
    assert train(scene, run, "--iterations", 1).exit_code == 0
    from velogauss.train.checkpoint import load_model

    model, _ = load_model(run)
    assert not model.velocity_at(torch.rand(8, 3), 0.5).any()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = invoke("render", run, "--no-labels")
    assert result.exit_code == 0, result.output
    assert [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)] == []
