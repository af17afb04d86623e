"""End-to-end: a small synthetic scene is trained for real and must be learned.

The expected values are physical facts of the generated scene, not outputs of the code under
test: the ground-truth velocity comes from the analytic scene (velogauss.scenes), and the
extrapolation is judged against the "freeze" baseline (the model held still at the last
observed time), which any model that learned no motion reproduces.
"""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.evaluate import evaluate_model, velocity_error
from velogauss.scenes import load_ground_truth, make_scene
from velogauss.train import loop

pytestmark = pytest.mark.slow

# A 32-pixel, 6-view, 11-time scene and a few hundred iterations: ~30 s on one CI core, long
# enough for the velocity field to be learned well past chance.
SMALL = ["train.iterations=450", "train.warmup=50", "train.curriculum=150", "train.eval_every=150",
         "train.checkpoint_every=150", "densify.start=50", "densify.every=50", "densify.until=350",
         "densify.opacity_reset_every=1000", "densify.static_every=100", "physics.n_points=256",
         "physics.ramp=150", "train.adf_start=250"]


def _trained(root, name, resolution, overrides):
    """(scene, ground truth, trained model) of the catalogue scene `name` at 6 views and 11 times."""
    make_scene(name, root / name, resolution=resolution, n_views=6, n_times=11, n_points=500, n_heldout=1)
    scene = load_scene(root / name)
    model = loop.train(load_config(None, overrides), scene, root / "run", progress=False)
    return scene, load_ground_truth(scene.root), model


def _velocity_errors(run):
    """(observed, future) particle velocity errors of a `_trained` run against its ground truth."""
    scene, truth, model = run
    err = velocity_error(model, truth, scene.max_time)
    return err["observed"]["relative_l2"], err["future"]["relative_l2"]


# The motion form these bounds were set with, which "auto" took from scene.json before it
# stopped reading it: the declared effects and the form they called for. The run's own choice,
# the backtest's (velogauss.train.backtest), is trained by test_cli_train_eval_render_export.
DECLARED = ["model.effects=declared", "model.incompressible=declared"]


@pytest.fixture(scope="module")
def spin_run(tmp_path_factory):
    return _trained(tmp_path_factory.mktemp("e2e"), "spin", 32, SMALL + DECLARED + ["model.patterns=rigid"])


def test_learned_velocity_matches_the_ground_truth(spin_run):
    observed, future = _velocity_errors(spin_run)
    # A zero field scores 1.0 and a random direction about 1.4. Seeds 0-2 of this set-up
    # (rigid motion patterns for this rigid scene, and the defaults: 3 views per step,
    # lambda_adf 10, collocation near the Gaussians, the mixing entropy, the acceleration
    # group's cooldown) learn the spin to 0.050-0.073 observed and 0.073-0.111 in the future
    # (without the cooldown 0.047-0.071 and 0.073-0.109; with the acceleration group's rate
    # decayed 100x over the whole schedule 0.121-0.141 and 0.155-0.218, which these bounds
    # fail). The bounds are 1.5x and 1.35x the worst seed, so a regression in the motion
    # model or the training shows here.
    assert observed < 0.11
    assert future < 0.15


def test_extrapolation_beats_holding_still(spin_run):
    scene, truth, model = spin_run
    result = evaluate_model(model, scene, splits=("interpolation", "extrapolation"), ground_truth=truth)
    extrap = result["splits"]["extrapolation"]["mean"]["psnr"]
    frozen = result["freeze_baseline"]["mean"]["psnr"]
    # Seeds 0-2: 6.7-7.7 dB above holding the last observed frame still, interpolation
    # 27.6-29.1 dB, future trajectories 4.7-6.2 % of the nothing-moved distance (without the
    # acceleration group's cooldown 7.0-7.8 dB, 27.6-29.0 dB and 4.1-5.9 %). The bounds leave
    # about 1.2 dB, 1.6 dB and 1.45x the worst seed.
    assert extrap > frozen + 5.5
    assert result["splits"]["interpolation"]["mean"]["psnr"] > 26.0
    traj = result["motion"]["trajectory"]
    assert traj["future"]["mean_distance"] < 0.09 * traj["future"]["static_mean_distance"]


# The periodic scene needs more: at 32 px and 450 iterations its oscillation was not learned
# (velocity error 0.62-0.64), at 64 px and 1200 iterations it is (~90 s on one CI core).
PERIODIC = ["train.iterations=1200", "train.warmup=100", "train.curriculum=500", "train.eval_every=0",
            "train.checkpoint_every=0", "densify.start=100", "densify.every=50", "densify.until=900",
            "densify.opacity_reset_every=100000", "densify.static_every=100", "physics.n_points=256",
            "physics.ramp=500", "train.adf_start=600"]


@pytest.fixture(scope="module")
def pulse_run(tmp_path_factory):
    harmonic = PERIODIC + DECLARED + ["model.patterns=harmonic"]
    return _trained(tmp_path_factory.mktemp("e2e_pulse"), "pulse", 64, harmonic)


def test_the_periodic_scene_is_learned_and_extrapolated(pulse_run):
    # pulse declares `oscillation`, its patterns are oscillators (VG-COEF-HARM), and the
    # transport residual is off ("auto"). Seeds 0-2 of this set-up: velocity error 0.021-0.025
    # observed and 0.057-0.073 future, extrapolation 8.4-9.4 dB above holding still (the
    # issue's target for the periodic scene is 3 dB; without the acceleration group's
    # cooldown 0.022-0.026, 0.058-0.074 and 8.1-9.2 dB); without the mixing entropy, from which
    # the bounds were set, 0.045-0.052, 0.096-0.097 and 7.0-7.2 dB. With the residual on they were
    # 0.17-0.21 / 0.19-0.23 and 4.8-6.8 dB, which these bounds fail; with the time network
    # (model.patterns = mlp, seed 0) 1.01 / 0.99, no motion at all, and 0.2 dB below.
    observed, future = _velocity_errors(pulse_run)
    assert observed < 0.08
    assert future < 0.14
    scene, truth, model = pulse_run
    result = evaluate_model(model, scene, splits=("extrapolation",), ground_truth=truth)
    assert result["splits"]["extrapolation"]["mean"]["psnr"] > result["freeze_baseline"]["mean"]["psnr"] + 5.0


def test_cli_train_eval_render_export(tmp_path):
    """The user's path through the CLI: default scene generated, trained, scored, drawn, exported."""
    runner = CliRunner()
    run = tmp_path / "run"
    tiny = ["train.iterations=20", "train.warmup=4", "train.curriculum=8", "train.eval_every=10",
            "train.checkpoint_every=10", "densify.start=4", "densify.every=8", "densify.until=16",
            "physics.n_points=32", "physics.ramp=4", "train.adf_start=8", "model.hidden=16",
            "model.depth=1", "model.n_patterns=4", "model.code_dim=4", "data.half_res=true"]
    args = ["train", "--out", str(run), "--no-eval"] + [a for s in tiny for a in ("--set", s)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert (run / "data" / "transforms_train.json").is_file()
    assert (run / "checkpoints" / "latest.pt").is_file()
    # The default patterns ("auto") were chosen by the backtest's probe, and config.toml records the choice.
    form = json.loads((run / "motion_form.json").read_text())
    assert form["choice"] in form["scores"] or not form["scores"]
    assert load_config(run / "config.toml").model.patterns in ("mlp", "rigid", "harmonic")
    # The user is told what was chosen, and whether the future holds.
    said = "holds" if form["future"] == "hold" else "integrated past the window"
    assert f"motion form: {form['choice']}" in result.output and said in result.output
    assert load_config(run / "config.toml").model.future == form["future"]

    result = runner.invoke(app, ["eval", str(run), "--split", "both"])
    assert result.exit_code == 0, result.output
    metrics = json.loads((run / "metrics.json").read_text())
    for split in ("interpolation", "extrapolation"):
        assert np.isfinite(metrics["splits"][split]["mean"]["psnr"])
    assert metrics["motion"]["velocity"]["points"] > 0
    assert (run / "metrics.md").read_text().startswith("#")
    # Scored beside the code that trained it, as the run folder recorded it.
    (trained,) = json.loads((run / "provenance.json").read_text())
    code = (trained["commit"] or "")[:7] or trained["version"]
    assert metrics["trained_by"] in (code, code + "+") and f"- trained by: `{metrics['trained_by']}`" in \
        (run / "metrics.md").read_text()

    result = runner.invoke(app, ["render", str(run), "--out", str(tmp_path / "renders")])
    assert result.exit_code == 0, result.output
    for name in ("sequence.mp4", "sequence.gif", "filmstrip.png", "velocity_field.png", "trajectories.png"):
        assert (tmp_path / "renders" / name).stat().st_size > 0

    result = runner.invoke(app, ["export", str(run), "--time", "0.5", "--out", str(tmp_path / "g.ply")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "g.ply").read_bytes().startswith(b"ply\n")
