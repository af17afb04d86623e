"""The forecast fitted to a trained model's paths (`model.future = "fit"`, velogauss.train.forecast),
and the backtest's rule that leaves a window its form does not reconstruct to the time network."""

import dataclasses
import types

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.model import build_model
from velogauss.model.motion import MotionParameters
from velogauss.model.spec import resolve_motion_spec
from velogauss.scenes import make_scene
from velogauss.train import backtest as backtest_module
from velogauss.train.backtest import candidate_spec, candidates, choose_form, window_psnr
from velogauss.train.checkpoint import load_model
from velogauss.train.loop import train
from velogauss_core.constants import FORM_WINDOW_DB, OSCILLATOR_WINDOW_DB, WINDOW_FRAMES

SMALL = ["model.n_patterns=4", "model.code_dim=4", "model.hidden=16", "model.depth=1"]
T = 0.5


def _spinning_forecast(cfg, omega, centre):
    """A rigid-drift forecast whose every pattern spins at `omega` (3,) about the still `centre` (3,)."""
    # A fine step: the test is of where the forecast takes the Gaussians, not of the integrator's error.
    spec = dataclasses.replace(candidate_spec(*candidates("auto")["rigid-drift"], cfg, T), step=1e-3)
    motion = MotionParameters(spec, np.random.default_rng(1))
    with torch.no_grad():
        motion.time.copy_(torch.as_tensor(np.concatenate([omega, centre, centre]), dtype=torch.float32))
    return motion.requires_grad_(False)


def _model(cfg, n=40):
    spec = resolve_motion_spec(cfg.model, None, T)
    points = np.random.default_rng(0).uniform(-0.5, 0.5, (n, 3))
    return build_model(cfg, spec, points, None, np.random.default_rng(0)).requires_grad_(False)


def test_past_the_window_the_forecast_moves_the_gaussians_on_from_their_state_there():
    cfg = load_config(None, [*SMALL, "model.patterns=mlp", "model.future=fit"])
    model = _model(cfg)
    before = [model.state_at(t) for t in (0.3, T, 0.8)]
    omega, centre = np.array([0.0, 0.6, 1.8]), np.array([0.1, -0.2, 0.05])
    model.set_forecast(_spinning_forecast(cfg, omega, centre))
    # Inside the window nothing changes, to the bit.
    for t, state in zip((0.3, T), before):
        for a, b in zip(model.state_at(t), state):
            assert torch.equal(a, b)
    # Past it: the state at T turned about the centre by |omega| (t - T), whatever the window's motion did.
    x_T, q_T, s_T, _ = before[1]
    turn = Rotation.from_rotvec(omega * (0.8 - T))
    x, q, s, _ = model.state_at(0.8)
    expected = centre + turn.apply(x_T.double().numpy() - centre)
    np.testing.assert_allclose(x.double().numpy(), expected, atol=2e-5)
    # The Gaussians turn with the body: q = r ⊗ q_T, up to sign (scipy's quaternions are (x, y, z, w)).
    turned = (turn * Rotation.from_quat(q_T.double().numpy()[:, [1, 2, 3, 0]])).as_quat()[:, [3, 0, 1, 2]]
    assert np.abs(np.abs((turned * q.double().numpy()).sum(1)) - 1).max() < 1e-5
    np.testing.assert_allclose(s.numpy(), s_T.numpy(), rtol=1e-5)
    # The velocity past the window is the forecast's: omega x (x - c).
    points = torch.as_tensor(expected[:5], dtype=torch.float32)
    v = model.particle_velocity(points, points, 0.8).double().numpy()
    np.testing.assert_allclose(v, np.cross(omega, expected[:5] - centre), atol=1e-5)
    v_field = model.velocity_at(points, 0.8).double().numpy()
    np.testing.assert_allclose(v_field, np.cross(omega, expected[:5] - centre), atol=1e-5)


def test_a_forecast_needs_a_spec_that_says_fit():
    cfg = load_config(None, [*SMALL, "model.patterns=mlp", "model.future=integrate"])
    model = _model(cfg)
    with pytest.raises(ValueError, match="forecast: the model's spec.future is 'integrate'"):
        model.set_forecast(_spinning_forecast(cfg, np.array([0.0, 0.0, 1.0]), np.zeros(3)))


def test_a_trained_forecast_is_recorded_and_comes_back_from_the_checkpoint(tmp_path):
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=8, n_points=300, n_heldout=1)
    scene = load_scene(tmp_path / "toss")
    cfg = load_config(None, [*SMALL, "train.iterations=40", "train.threads=1", "model.patterns=mlp",
                             "model.future=fit"])
    model = train(cfg, scene, tmp_path / "run", progress=False)
    report = (tmp_path / "run" / "forecast.json").read_text()
    # The future the end of training chose is the model's, and the checkpoint's.
    assert model.spec.future in {"fit", "integrate", "hold"} and f'"future": "{model.spec.future}"' in report
    assert (model.forecast is not None) == (model.spec.future == "fit")
    loaded, _ = load_model(tmp_path / "run")
    assert loaded.spec == model.spec and (loaded.forecast is None) == (model.forecast is None)
    for a, b in zip(loaded.state_at(0.95), model.state_at(0.95)):
        assert torch.equal(a, b)


class _Renders:
    """A stand-in model for `window_psnr`: renders each frame's own image, offset by `offset`."""

    def __init__(self, frames, offset):
        self.images = {id(f.camera): torch.as_tensor(f.image) for f in frames}
        self.offset = offset
        self.gaussians = types.SimpleNamespace(means=torch.zeros(1, 3))

    def render(self, camera, t, background):
        image = self.images.get(id(camera))
        return (torch.zeros(1, 1, 3) if image is None else image + self.offset), None, None


def test_the_window_psnr_scores_training_frames_never_the_held_out_ones(tmp_path):
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=8, n_points=300, n_heldout=1)
    scene = load_scene(tmp_path / "toss")
    assert scene.interpolation and len(scene.train) > WINDOW_FRAMES
    # Every training frame rendered exactly: the 100 dB cap; the held-out frames, rendered black, are not read.
    assert window_psnr(_Renders(scene.train, 0.0), scene) == pytest.approx(100.0)
    # Off by 0.1 before the renders' clamp to [0, 1]: the mean over WINDOW_FRAMES of them, evenly spread.
    frames = [scene.train[i] for i in np.linspace(0, len(scene.train) - 1, WINDOW_FRAMES).round().astype(int)]
    expected = np.mean([10 * np.log10(1 / np.mean((np.clip(f.image - 0.1, 0, 1) - f.image) ** 2)) for f in frames])
    assert window_psnr(_Renders(scene.train, -0.1), scene) == pytest.approx(expected, abs=1e-3)


def test_a_form_that_reconstructs_the_window_worse_leaves_it_to_the_time_network(tmp_path, monkeypatch):
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=8, n_points=300, n_heldout=1)
    scene = load_scene(tmp_path / "toss")
    times = np.linspace(0.0, 0.5, 8)
    monkeypatch.setattr(backtest_module, "probe_paths", lambda model, data, rng: (times, np.zeros((8, 60, 3))))
    scores = {"rigid-drift": [0.5, 0.4, 0.4], "rigid": [0.1, 0.1, 0.1], "harmonic": [0.3, 0.2, 0.2], "mlp": [0.4] * 3}
    monkeypatch.setattr(backtest_module, "backtest", lambda *args: scores)
    monkeypatch.setattr(backtest_module, "window_psnr", lambda model, data: model.db)
    probes = []

    def probe(cfg, data, folder, progress=False, frequency=None, form_db=34.5):
        probes.append(cfg.model.patterns)
        return types.SimpleNamespace(moving=torch.ones(60, dtype=torch.bool),
                                     db=35.0 if cfg.model.patterns == "mlp" else form_db)

    cfg = load_config(None, [*SMALL, "train.iterations=30"])
    # Within FORM_WINDOW_DB of the time network's probe: the chosen form trains the window.
    chosen, report = choose_form(cfg, scene, probe)
    assert probes == ["mlp", "rigid"] and report["window_psnr"]["rigid"] == 34.5
    assert (chosen.model.patterns, chosen.model.future, report["choice"]) == ("rigid", "integrate", "rigid")
    # Worse by more: the time network trains the window, and the forecast is fitted after it.
    worse = 35.0 - FORM_WINDOW_DB - 0.5
    chosen, report = choose_form(cfg, scene, lambda *a, **k: probe(*a, **k, form_db=worse))
    assert (chosen.model.patterns, chosen.model.future, report["choice"], report["patterns"]) == (
        "mlp", "fit", "rigid", "mlp")
    # A future the user set keeps the chosen form on the window, with no second probe.
    probes.clear()
    kept = load_config(None, [*SMALL, "train.iterations=30", "model.future=integrate"])
    assert choose_form(kept, scene, probe)[0].model.patterns == "rigid" and probes == ["mlp"]


def _stubbed_probes(tmp_path, monkeypatch, first, second, first_db, dbs):
    """A small scene, and choose_form's probes, paths, backtest and window PSNR stubbed: each
    probe's model carries its window PSNR `dbs(patterns)`, its paths carry that PSNR, and the
    backtest scores paths of `first_db` (the time network's) as `first`, the others as `second`.
    Returns (scene, probe, probes: the patterns each probe was trained with)."""
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=8, n_points=300, n_heldout=1)
    scene = load_scene(tmp_path / "toss")
    times = np.linspace(0.0, 0.5, 8)
    monkeypatch.setattr(backtest_module, "probe_paths",
                        lambda model, data, rng: (times, np.full((8, 60, 3), model.db)))
    monkeypatch.setattr(backtest_module, "backtest",
                        lambda times, paths, *args: first if paths[0, 0, 0] == first_db else second)
    monkeypatch.setattr(backtest_module, "window_psnr", lambda model, data: model.db)
    probes = []

    def probe(cfg, data, folder, progress=False, frequency=None):
        probes.append(cfg.model.patterns)
        return types.SimpleNamespace(moving=torch.ones(60, dtype=torch.bool), db=dbs(cfg.model.patterns))

    return scene, probe, probes


@pytest.mark.parametrize(("harmonic_db", "tail", "patterns", "future"), [
    (35.0 + OSCILLATOR_WINDOW_DB + 0.5, 0.5, "harmonic", "integrate"),  # the oscillators reconstruct it better
    (35.0 + OSCILLATOR_WINDOW_DB + 0.5, 1.2, "harmonic", "hold"),  # ... but their paths forecast worse than freezing
    (35.0 + OSCILLATOR_WINDOW_DB - 0.5, 0.5, "mlp", "integrate"),  # within the margin: the time network's window
])
def test_a_window_the_time_network_was_chosen_for_goes_to_the_oscillators_if_they_reconstruct_it_better(
        tmp_path, monkeypatch, harmonic_db, tail, patterns, future):
    # Each probe's paths tell which probe they came from, and the backtest scores them accordingly.
    first = {"rigid": [1.5] * 3, "harmonic": [1.3] * 3, "mlp": [0.6] * 3}
    second = {"rigid": [1.5] * 3, "harmonic": [tail] * 3, "mlp": [0.9] * 3}
    scene, probe, probes = _stubbed_probes(tmp_path, monkeypatch, first, second, 35.0,
                                           lambda patterns: 35.0 if patterns == "mlp" else harmonic_db)
    cfg = load_config(None, [*SMALL, "train.iterations=30"])
    chosen, report = choose_form(cfg, scene, probe)
    assert probes == ["mlp", "harmonic"] and report["window_psnr"]["harmonic"] == harmonic_db
    assert (chosen.model.patterns, chosen.model.future, report["future"]) == (patterns, future, future)
    assert report["choice"] == patterns
    if patterns == "harmonic":  # the oscillators' own paths scored the future; the first probe's are kept
        assert report["scores"] is second and report["first_scores"] is first
    else:
        assert report["scores"] is first and "first_scores" not in report
    # A future the user set: no second probe, the time network.
    probes.clear()
    kept = load_config(None, [*SMALL, "train.iterations=30", "model.future=integrate"])
    assert choose_form(kept, scene, probe)[0].model.patterns == "mlp" and probes == ["mlp"]


def test_a_window_a_form_lost_to_the_time_network_goes_to_the_oscillators_if_they_reconstruct_it_better(
        tmp_path, monkeypatch):
    first = {"rigid-drift": [0.8] * 3, "rigid": [1.5] * 3, "harmonic": [0.9] * 3, "mlp": [0.85] * 3}
    second = {"rigid-drift": [1.5] * 3, "rigid": [1.5] * 3, "harmonic": [0.2] * 3, "mlp": [0.9] * 3}
    dbs = {"mlp": 23.0, "rigid": 20.0, "harmonic": 23.0 + OSCILLATOR_WINDOW_DB + 0.5}
    scene, probe, probes = _stubbed_probes(tmp_path, monkeypatch, first, second, 23.0, dbs.__getitem__)
    cfg = load_config(None, [*SMALL, "train.iterations=30"])
    chosen, report = choose_form(cfg, scene, probe)
    # rigid-drift forecast the first paths best but reconstructed the window worse than the time
    # network; the oscillators reconstruct it better than both, and their paths forecast.
    assert probes == ["mlp", "rigid", "harmonic"]
    assert report["window_psnr"] == {"mlp": 23.0, "rigid-drift": 20.0, "harmonic": dbs["harmonic"],
                                     "probe_s": report["window_psnr"]["probe_s"]}
    assert (chosen.model.patterns, chosen.model.future, report["choice"], report["first_choice"]) == (
        "harmonic", "integrate", "harmonic", "rigid-drift")
    assert report["scores"] is second and report["first_scores"] is first
