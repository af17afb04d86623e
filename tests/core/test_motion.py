"""velogauss_core.motion: `MotionSpec` validates a spec built directly, with the ranges
its sizes take from `NetworkSizes` (spec/motion.md, "Parameters and configuration")."""

import dataclasses

import numpy as np
import pytest

from velogauss_core.motion import MotionSpec, NetworkSizes, init_motion_params


def test_sizes_come_first_then_what_the_equations_read():
    names = [f.name for f in dataclasses.fields(MotionSpec)]
    sizes = [f.name for f in dataclasses.fields(NetworkSizes)]
    assert names[:len(sizes) + 6] == sizes + ["mask", "acc_mask", "acc_form", "pattern_form", "max_time", "rigid_knots"]


@pytest.mark.parametrize("sizes, message", [
    ({"n_freqs_x": 17}, r"n_freqs_x: expected an integer in \[0, 16\], got 17"),  # above NetworkSizes' bound
    ({"n_freqs_adf_t": -1}, r"n_freqs_adf_t: expected an integer in \[0, 16\], got -1"),
    ({"hidden": 0}, r"hidden: expected an integer >= 1, got 0"),
    ({"depth": True}, r"depth: expected an integer >= 1, got True"),  # a bool is not a size
    ({"n_patterns": 4.0}, r"n_patterns: expected an integer >= 1, got 4.0"),
    ({"mask": (True,) * 3}, r"mask: expected 12 booleans"),
    ({"acc_form": "cubic"}, r"acc_form: expected one of"),
    ({"pattern_form": "spline"}, r"pattern_form: expected one of"),
    ({"max_time": 0.0}, r"max_time: expected a time in \(0, 1\], got 0.0"),
    ({"max_time": float("nan")}, r"max_time: expected a finite real scalar"),
    ({"rigid_knots": 4}, r"rigid_knots: expected 2 or 3, got 4"),
    ({"acc_form": "harmonic"}, r"acc_form: 'harmonic' takes the harmonic patterns' frequencies, got "
                               r"pattern_form 'mlp'"),
])
def test_bad_values_are_named(sizes, message):
    with pytest.raises(ValueError, match=message):
        MotionSpec(**sizes)


def test_bounds_and_numpy_integers_are_accepted():
    cfg = MotionSpec(n_freqs_x=16, n_freqs_t=0, hidden=np.int64(1))
    assert (cfg.n_freqs_x, cfg.n_freqs_t, cfg.hidden) == (16, 0, 1)


def test_frozen_and_hashable():
    cfg = MotionSpec(mask=np.ones(12, dtype=bool))
    assert cfg.mask == (True,) * 12  # stored as a tuple, so the spec hashes
    assert hash(cfg) == hash(MotionSpec(mask=(True,) * 12))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.hidden = 8


def test_harmonic_patterns_start_still_at_one_cycle():
    # VG-COEF-HARM: zero coefficients (a still scene) and one shared frequency, one cycle over
    # the window (training then sets the video's); the acceleration's harmonics start at zero.
    cfg = MotionSpec(n_patterns=4, pattern_form="harmonic", acc_form="harmonic", max_time=0.5)
    params = init_motion_params(np.random.default_rng(0), cfg)
    [(C, omega)], Q = params["time"], params["acc"]
    assert C.shape == (3, 4, 12) and np.all(C == 0) and Q.shape == (5, 4, 12) and np.all(Q == 0)
    np.testing.assert_allclose(omega, [2 * np.pi / 0.5], rtol=1e-12)
