"""velogauss_core.motion: `MotionConfig` validates a config built directly, with the ranges
its sizes take from `MotionSizes` (spec/motion.md, "Parameters and configuration")."""

import dataclasses

import numpy as np
import pytest

from velogauss_core.motion import MotionConfig, MotionSizes


def test_sizes_come_first_then_masks():
    names = [f.name for f in dataclasses.fields(MotionConfig)]
    assert names == [f.name for f in dataclasses.fields(MotionSizes)] + ["mask", "acc_mask", "acc_form", "pattern_form", "max_time",
                                                                   "rigid_knots"]


@pytest.mark.parametrize("sizes, message", [
    ({"n_freqs_x": 17}, r"n_freqs_x: expected an integer in \[0, 16\], got 17"),  # above MotionSizes' bound
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
])
def test_bad_values_are_named(sizes, message):
    with pytest.raises(ValueError, match=message):
        MotionConfig(**sizes)


def test_bounds_and_numpy_integers_are_accepted():
    cfg = MotionConfig(n_freqs_x=16, n_freqs_t=0, hidden=np.int64(1))
    assert (cfg.n_freqs_x, cfg.n_freqs_t, cfg.hidden) == (16, 0, 1)


def test_frozen_and_hashable():
    cfg = MotionConfig(mask=np.ones(12, dtype=bool))
    assert cfg.mask == (True,) * 12  # stored as a tuple, so the config hashes
    assert hash(cfg) == hash(MotionConfig(mask=(True,) * 12))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.hidden = 8
