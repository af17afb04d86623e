"""Tests of velogauss/train/backtest.py: the motion patterns' form chosen by backtesting paths.

Every expected value comes from the paths' construction (an exact rigid motion, an exact
oscillation), never from the code under test.
"""

import numpy as np
import pytest
import torch

from velogauss.config import load_config
from velogauss.data import load_scene
from velogauss.scenes import make_scene
from velogauss.train.backtest import (CANDIDATES, backtest, beats_freezing, candidate_spec, candidates, choose_form,
                                      harmonic_fit, leaves_a_future, origins, probe_config, rigid_fit, select)
from velogauss.train.frequency import series_frequency
from velogauss_core.constants import BACKTEST_HEADS, FREQ_SCAN_STEP
from velogauss_fast.motion.basis import basis_matrix
from velogauss_fast.motion.coefficients import harmonic_velocity_patterns, rigid_velocity_patterns

TIMES = np.linspace(0.0, 0.75, 16)
SMALL = ["model.n_patterns=4", "model.code_dim=4", "model.hidden=16", "model.depth=1"]


@pytest.fixture()
def tiny_scene(tmp_path):
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=6, n_points=300, n_heldout=1)
    return load_scene(tmp_path / "toss")


def _rotation(axis, angle):
    """(3, 3) rotation by `angle` about the unit `axis` (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _body(seed=0, n=60):
    return np.random.default_rng(seed).uniform(-0.3, 0.3, (n, 3))


def _tossed(times, spin=4.0, launch=(0.8, 0.2, 1.5), gravity=-3.0, centre=(0.2, -0.1, 0.0)):
    """Paths (J, M, 3) of a body spinning at `spin` rad per unit time about a tilted axis while its
    centre flies on a parabola, and the truth: (omega (3,), centre (J, 3))."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    body = _body()
    c = np.asarray(centre) + np.outer(times, launch) + 0.5 * gravity * np.outer(times ** 2, [0, 0, 1])
    paths = np.stack([c[j] + body @ _rotation(axis, spin * t).T for j, t in enumerate(times)])
    return paths, spin * axis, c


def _pulsing(times, omega=9.0, amplitude=0.3):
    """Paths of a body whose three semi-axes oscillate out of phase: x_d(t) = x_d(0) (1 + a sin(Ω t + φ_d))."""
    body = _body(1)
    phases = np.array([0.0, 2.0, 4.0])
    return np.stack([body * (1 + amplitude * np.sin(omega * t + phases)) for t in times])


def test_the_rigid_fit_recovers_an_exact_rigid_motion():
    paths, omega, centre = _tossed(TIMES)
    velocities = np.gradient(paths, TIMES, axis=0)
    # Exact velocities, not finite differences: v = ω × (x − c) + ċ.
    c_dot = np.array([0.8, 0.2, 1.5]) + np.outer(TIMES, [0, 0, -3.0])
    velocities = np.cross(omega, paths - centre[:, None]) + c_dot[:, None]
    cfg = load_config(None, SMALL)
    spec = candidate_spec(*candidates("auto")["rigid"], cfg, float(TIMES[-1]))
    row = rigid_fit(TIMES, paths, velocities, spec)
    np.testing.assert_allclose(row[:3], omega, atol=1e-9)
    # The fitted patterns reproduce the true velocity field at every time.
    B = torch.as_tensor(row[None])
    P = rigid_velocity_patterns(B, torch.as_tensor(TIMES)[:, None, None], spec.max_time)[:, 0].numpy()  # [J, 12]
    fitted = P[:, None, :3] + np.cross(P[:, None, 3:6], paths)
    np.testing.assert_allclose(fitted, velocities, atol=1e-9)


def test_the_harmonic_fit_recovers_an_exact_oscillating_field():
    omega = 7.0
    rng = np.random.default_rng(2)
    blocks = rng.normal(size=(3, 12))
    x = np.stack([_body(3) for _ in TIMES])
    C = torch.as_tensor(blocks[:, None])  # [3, 1, 12]
    w = harmonic_velocity_patterns(C, torch.tensor([omega], dtype=torch.float64),
                                   torch.as_tensor(TIMES)[:, None, None])[:, 0].numpy()  # [J, 12]
    v = np.einsum("jmdc,jc->jmd", basis_matrix(torch.as_tensor(x)).numpy(), w)
    np.testing.assert_allclose(harmonic_fit(TIMES, x, v, omega, None), blocks, atol=1e-8)


@pytest.mark.parametrize("cycles", [0.8, 1.6, 2.4])
def test_the_paths_frequency_is_the_oscillation_s(cycles):
    omega = 2 * np.pi * cycles / TIMES[-1]
    paths = _pulsing(TIMES, omega=omega)
    found = series_frequency(TIMES, paths.reshape(len(TIMES), -1), float(TIMES[-1]))
    assert abs(found - omega) <= 2 * np.pi * FREQ_SCAN_STEP / TIMES[-1]


@pytest.mark.parametrize("paths, expected", [
    (_tossed(np.linspace(0.0, 0.75, 16))[0], {"rigid"}),
    (_pulsing(np.linspace(0.0, 0.75, 16)), {"harmonic"}),
], ids=["tossed-and-tumbling", "pulsing"])
def test_the_backtest_prefers_the_form_the_paths_were_made_with(paths, expected):
    cfg = load_config(None, SMALL)
    scores = backtest(TIMES, paths, cfg, np.random.default_rng(0))
    assert list(scores) == list(CANDIDATES) and all(len(row) == len(origins(TIMES)) for row in scores.values())
    assert select(scores) in expected
    # The winner's tail error is at most half of freezing the motion at the head's end (1);
    # the pulse's field, (ds/dt) / s, is an oscillation only to first order in its amplitude.
    assert max(scores[select(scores)]) < 0.5


@pytest.mark.parametrize("n_times, n_paths", [(3, 10), (16, 0)], ids=["no-tail", "nothing-moved"])
def test_the_backtest_scores_nothing_without_a_tail_or_a_path(n_times, n_paths):
    times = np.linspace(0.0, 0.75, n_times)
    paths = _tossed(times)[0][:, :n_paths]
    scores = backtest(times, paths, load_config(None, SMALL), np.random.default_rng(0))
    assert scores == {} and select(scores) == "mlp" and not beats_freezing(scores, "mlp")


def test_a_richer_form_is_chosen_only_when_it_predicts_better_at_every_origin():
    # The default scene's seed 1 at one origin: oscillators 0.258 against rigid 0.270.
    scores = {"rigid-drift": [0.43, 0.65, 0.72], "rigid": [0.30, 0.29, 0.27], "harmonic": [0.37, 0.30, 0.26],
              "mlp": [0.43, 0.51, 0.62]}
    assert select(scores) == "rigid"
    scores["harmonic"] = [0.29, 0.28, 0.26]
    assert select(scores) == "harmonic"
    # The simplest form is kept over richer ones that win only somewhere.
    assert select({"rigid-drift": [0.2, 0.2], "rigid": [0.1, 0.3], "mlp": [0.3, 0.1]}) == "rigid-drift"
    # A choice no better than freezing on average, or no score at all: the time network.
    assert select({"rigid": [0.9, 1.2], "harmonic": [1.5, 1.3], "mlp": [1.1, 1.4]}) == "mlp"
    assert select({}) == "mlp"


def test_the_future_holds_when_no_form_beats_freezing():
    # The mean score of the choice decides, as for the choice itself.
    assert beats_freezing({"rigid": [0.9, 1.05], "mlp": [1.1, 1.4]}, "rigid")
    scores = {"rigid": [0.9, 1.2], "harmonic": [1.5, 1.3], "mlp": [1.1, 1.4]}
    assert select(scores) == "mlp" and not beats_freezing(scores, "mlp")
    # No paths to score (nothing moved, or too few times): nothing was shown to beat freezing.
    assert not beats_freezing({}, select({}))


def test_the_origins_are_the_heads_last_times_with_a_tail_to_score():
    # 16 times j / 15 of the window: the last at or before 0.5, 0.6 and 0.7 are j = 7, 9, 10.
    assert BACKTEST_HEADS == (0.5, 0.6, 0.7) and origins(TIMES) == [7, 9, 10]
    few = np.array([0.0, 0.1, 0.2, 0.3])  # 3 times to fit and 1 to score, whatever the shares
    assert origins(few) == [2]


def test_a_choice_is_written_into_the_config_and_never_read_from_the_scene(tiny_scene):
    cfg = load_config(None, [*SMALL, "train.iterations=30", "train.threads=1"])

    shapes = []

    def probe_run(probe_cfg, data, folder, progress=True, frequency=None):
        # The time network's first; a second to see whether a chosen form reconstructs the window,
        # or, where the time network was chosen, whether the oscillators reconstruct it better.
        shapes.append(probe_cfg.model.patterns)
        assert shapes[0] == "mlp" and len(shapes) <= 2 and probe_cfg.train.iterations == 10
        from velogauss.train.loop import train
        return train(probe_cfg, data, folder, progress=progress, frequency=frequency)

    chosen, report = choose_form(cfg, tiny_scene, probe_run)
    assert len(shapes) == 2 and shapes[1] == (CANDIDATES[report["choice"]][0] if report["choice"] != "mlp" else "harmonic")
    assert chosen.model.patterns in {"mlp", "rigid", "harmonic"}
    assert report["choice"] in CANDIDATES and chosen.model.mixing_init in {"uniform", "clusters"}
    # The future follows the report's scores: held exactly when the choice did not beat freezing.
    if report["patterns"] == "mlp" and report["choice"] != "mlp":  # the form did not reconstruct the window
        assert chosen.model.future == report["future"] == "fit"
    else:
        assert chosen.model.future == report["future"] == ("integrate" if beats_freezing(report["scores"],
                                                                                          report["choice"]) else "hold")
    # A future the user set is kept.
    kept = load_config(None, [*SMALL, "train.iterations=30", "train.threads=1", "model.future=integrate"])
    shapes.clear()
    assert choose_form(kept, tiny_scene, probe_run)[0].model.future == "integrate"
    # The same data with other declared effects chooses the same: the declaration is not read.
    tiny_scene.metadata["effects"] = ["stretch", "oscillation"]
    shapes.clear()
    again, _ = choose_form(cfg, tiny_scene, probe_run)
    assert again == chosen


def test_a_window_that_reaches_the_end_of_time_takes_the_time_network_without_a_probe(tmp_path):
    make_scene("toss", tmp_path / "toss", resolution=24, n_views=4, n_times=6, n_points=300, n_heldout=1)
    every_frame = load_scene(tmp_path / "toss", split="all")  # trained up to t = 1
    ending_early = load_scene(tmp_path / "toss")  # trained up to t = 0.6, frames 0.2 apart
    assert not leaves_a_future(every_frame) and leaves_a_future(ending_early)

    def no_probe(*args, **kwargs):
        raise AssertionError("a window with nothing to forecast trains no probe")

    cfg = load_config(None, [*SMALL, "train.iterations=30"])
    chosen, report = choose_form(cfg, every_frame, no_probe)
    assert (chosen.model.patterns, chosen.model.mixing_init, chosen.model.future) == ("mlp", "uniform", "integrate")
    assert report["choice"] == "mlp" and report["scores"] == {}
    # What the user set is kept.
    kept = load_config(None, [*SMALL, "model.mixing_init=clusters", "model.future=hold"])
    kept_model = choose_form(kept, every_frame, no_probe)[0].model
    assert (kept_model.mixing_init, kept_model.future) == ("clusters", "hold")


def test_the_probe_s_schedule_scales_with_it_whether_set_or_auto():
    # A third of 900 iterations: every schedule key a third of the run's, set or "auto", so that
    # the probe's window opens as the run's does (a set curriculum of 600 would never open in 300).
    cfg = load_config(None, ["train.iterations=900", "train.curriculum=600", "densify.every=2"])
    probe = probe_config(cfg)
    assert probe.train.iterations == 300 and probe.model.patterns == "mlp"
    assert probe.train.curriculum == 200 and probe.densify.every == 1  # an interval stays at least 1
    assert probe.train.warmup == round(200 * 900 / 3000 / 3)  # "auto": SCHEDULE's share of 900, a third
    assert probe.train.eval_every == 0 and probe.train.checkpoint_every == 0


def test_the_candidates_keep_within_the_effects_a_user_allows():
    every = ("translation", "rotation", "gravity", "stretch", "shear", "static")
    assert candidates("auto") == {"mlp": ("mlp", every), "harmonic": ("harmonic", every),
                                  "rigid": ("rigid", ("translation", "rotation", "gravity", "static")),
                                  "rigid-drift": ("rigid", ("translation", "rotation", "static"))}
    # No gravity declared: one rigid candidate; only stretch: no rigid one at all.
    assert candidates(("translation", "rotation")) == {"mlp": ("mlp", ("translation", "rotation")),
                                                       "rigid": ("rigid", ("translation", "rotation")),
                                                       "harmonic": ("harmonic", ("translation", "rotation"))}
    assert set(candidates(("stretch",))) == {"mlp", "harmonic"}

