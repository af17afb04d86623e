"""Tests of velogauss/train/frequency.py: the starting frequency of harmonic patterns, read off the video."""

from types import SimpleNamespace

import numpy as np
import pytest

from velogauss.config import load_config
from velogauss.model import build_model, scene_spec
from velogauss.train.frequency import candidate_frequencies, start_frequency, video_frequency
from velogauss_core.constants import FREQ_SCAN_STEP

WINDOW = 0.75
TIMES = np.linspace(0.0, 1.0, 21)


def _video(omega, cameras=3, times=TIMES, after=None, seed=0):
    """Frames of `cameras` fixed views whose pixels oscillate at `omega` with random phases,
    amplitudes and noise (times past the window at `after`, when given, instead)."""
    rng = np.random.default_rng(seed)
    frames = []
    for c in range(cameras):
        camera = SimpleNamespace(viewmat=np.eye(4) + np.eye(4, k=3) * c)
        phase, amplitude = rng.uniform(0, 2 * np.pi, (8, 8)), rng.uniform(0, 0.3, (8, 8))
        for t in times:
            w = after if after is not None and t > WINDOW else omega
            grey = 0.5 + amplitude * np.sin(w * t + phase) + 0.02 * rng.standard_normal((8, 8))
            frames.append(SimpleNamespace(camera=camera, time=float(t), image=np.repeat(grey[..., None], 3, -1)))
    return frames


@pytest.mark.parametrize("cycles", [0.6, 1.125, 1.9, 2.7])
def test_the_scan_finds_the_frequency_the_pixels_oscillate_at(cycles):
    omega = 2 * np.pi * cycles / WINDOW
    found = video_frequency(_video(omega), WINDOW)
    assert abs(found - omega) <= 2 * np.pi * FREQ_SCAN_STEP / WINDOW


def test_a_large_video_is_scanned_through_a_pixel_stride(monkeypatch):
    # Fewer pixels than the image has (FREQ_SCAN_PIXELS): the same frequency from a stride.
    omega = 2 * np.pi * 1.7 / WINDOW
    monkeypatch.setattr("velogauss.train.frequency.FREQ_SCAN_PIXELS", 10)
    assert abs(video_frequency(_video(omega), WINDOW) - omega) <= 2 * np.pi * FREQ_SCAN_STEP / WINDOW


def test_frames_past_the_window_do_not_count():
    inside = 2 * np.pi * 1.4 / WINDOW
    found = video_frequency(_video(inside, after=3 * inside), WINDOW)
    assert abs(found - inside) <= 2 * np.pi * FREQ_SCAN_STEP / WINDOW


def test_a_monocular_video_gives_no_estimate():
    # One view per time (every frame its own camera), or too few times per camera.
    frames = _video(9.0, cameras=1)
    for i, frame in enumerate(frames):
        frame.camera = SimpleNamespace(viewmat=np.eye(4) * (1 + i))
    assert video_frequency(frames, WINDOW) is None
    assert video_frequency(_video(9.0, times=TIMES[:3]), WINDOW) is None


def test_candidates_span_the_scan_in_cycles_over_the_window():
    cycles = candidate_frequencies(0.5) * 0.5 / (2 * np.pi)
    np.testing.assert_allclose([cycles[0], cycles[-1]], [0.25, 3.0])
    np.testing.assert_allclose(np.diff(cycles), FREQ_SCAN_STEP)


def _model(effects, patterns="auto"):
    """A model of a scene that declares `effects`, taken as declared ("auto" would ignore them)."""
    cfg = load_config(None, ["model.effects=declared", f"model.patterns={patterns}", f"data.max_time={WINDOW}"])
    spec = scene_spec(cfg, {"effects": list(effects), "incompressible": True})
    return build_model(cfg, spec, np.random.default_rng(0).standard_normal((20, 3)), None,
                       np.random.default_rng(0))


def test_a_harmonic_model_starts_at_the_video_frequency():
    model = _model(("stretch", "oscillation"), "harmonic")
    assert model.spec.pattern_form == "harmonic"
    omega = 2 * np.pi * 1.3 / WINDOW
    assert start_frequency(model, _video(omega), WINDOW) == pytest.approx(omega, abs=0.3)
    assert float(model.motion.time[1].detach()[0]) == pytest.approx(omega, abs=0.3)
    # Without an estimate it keeps HARMONIC_CYCLES_INIT (one cycle over the window).
    fresh = _model(("stretch", "oscillation"), "harmonic")
    assert start_frequency(fresh, _video(omega, times=TIMES[:3]), WINDOW) is None
    assert float(fresh.motion.time[1].detach()[0]) == pytest.approx(2 * np.pi / WINDOW)


def test_without_a_video_estimate_the_backtest_s_frequency_starts_it():
    # A monocular video gives no estimate; the probe's paths' frequency (the fallback) is used,
    # and a video estimate, when there is one, wins over it.
    omega = 2 * np.pi * 1.3 / WINDOW
    monocular = _model(("stretch", "oscillation"), "harmonic")
    assert start_frequency(monocular, _video(omega, times=TIMES[:3]), WINDOW, fallback=7.5) == 7.5
    assert float(monocular.motion.time[1].detach()[0]) == pytest.approx(7.5)
    seen = _model(("stretch", "oscillation"), "harmonic")
    assert start_frequency(seen, _video(omega), WINDOW, fallback=7.5) == pytest.approx(omega, abs=0.3)


def test_other_patterns_are_left_alone():
    model = _model(("stretch",))
    before = [p.detach().clone() for p in model.motion.parameters()]
    assert start_frequency(model, _video(9.0), WINDOW) is None
    assert all(bool((a == b).all()) for a, b in zip(before, model.motion.parameters()))
