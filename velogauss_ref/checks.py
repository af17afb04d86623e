"""Input validation shared by the reference functions (spec/conventions.md, "Bad input").

Bad input raises ValueError naming the argument, never a deep traceback or a silent NaN.
Works on plain arrays and on autograd's traced boxes alike.
"""

import numpy as onp
from autograd.tracer import getval


def check_array(name, x, shape=None):
    """Raise ValueError unless `x` is finite and matches `shape`.

    `shape` is a tuple whose entries are ints (exact size), None (any size) or the
    string "..." as the first entry (any leading batch dimensions).
    Returns `x` unchanged so calls can be chained.
    """
    value = onp.asarray(getval(x))
    if shape is not None and not _shape_matches(value.shape, shape):
        raise ValueError(f"{name}: expected shape {_fmt(shape)}, got {value.shape}")
    if value.dtype.kind not in "biuf":
        raise ValueError(f"{name}: expected a real numeric array, got dtype {value.dtype}")
    if not onp.all(onp.isfinite(value)):
        bad = int(onp.size(value) - onp.count_nonzero(onp.isfinite(value)))
        raise ValueError(f"{name}: contains {bad} non-finite value(s) (NaN or inf)")
    return x


def check_scalar(name, x):
    """Raise ValueError unless `x` is a finite real scalar; return it as float."""
    value = onp.asarray(getval(x))
    if value.shape != () or value.dtype.kind not in "biuf" or not onp.isfinite(value):
        raise ValueError(f"{name}: expected a finite real scalar, got {value!r}")
    return x


def _shape_matches(actual, expected):
    if expected and expected[0] == "...":
        tail = expected[1:]
        if len(actual) < len(tail):
            return False
        actual = actual[len(actual) - len(tail):]
        expected = tail
    if len(actual) != len(expected):
        return False
    return all(e is None or a == e for a, e in zip(actual, expected))


def _fmt(shape):
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
