"""Input checks shared by every package (spec/conventions.md, "Bad input").

Bad input raises ValueError whose message starts with the argument's name, never a deep
traceback or a silent NaN. `check_array` here takes NumPy arrays and anything NumPy can
read; `velogauss_ref.checks` unwraps autograd's traced boxes first and
`velogauss_fast.checks` checks tensors on their own device, both with `shape_matches`.
"""

import numpy as np

# A shape pattern: ints (exact size), None (any size), and optionally "..." first (any
# leading batch dimensions).
Shape = tuple


def check_array(name: str, x, shape: Shape | None = None):
    """Raise ValueError unless `x` is a finite real array matching `shape`; return `x`."""
    value = np.asarray(x)
    if shape is not None and not shape_matches(value.shape, shape):
        raise ValueError(f"{name}: expected shape {format_shape(shape)}, got {value.shape}")
    if value.dtype.kind not in "biuf":
        raise ValueError(f"{name}: expected a real numeric array, got dtype {value.dtype}")
    if not np.all(np.isfinite(value)):
        bad = int(np.size(value) - np.count_nonzero(np.isfinite(value)))
        raise ValueError(f"{name}: contains {bad} non-finite value(s) (NaN or inf)")
    return x


def check_scalar(name: str, x):
    """Raise ValueError unless `x` is a finite real scalar; return `x`."""
    value = np.asarray(x)
    if value.shape != () or value.dtype.kind not in "biuf" or not np.isfinite(value):
        raise ValueError(f"{name}: expected a finite real scalar, got {value!r}")
    return x


def check_size(name: str, n) -> int:
    """Raise ValueError unless `n` is a positive int (an image width or height); return it."""
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise ValueError(f"{name}: expected a positive int, got {n!r}")
    return int(n)


def check_degree(name: str, degree) -> int:
    """Raise ValueError unless `degree` is an int SH degree in {0, 1, 2, 3}; return it."""
    if isinstance(degree, (bool, np.bool_)) or not isinstance(degree, (int, np.integer)) or not 0 <= degree <= 3:
        raise ValueError(f"{name}: expected 0, 1, 2 or 3, got {degree!r}")
    return int(degree)


def check_weight(name: str, value):
    """Raise ValueError naming `name` unless `value` is a finite real number >= 0; return it."""
    check_scalar(name, value)
    if value < 0:
        raise ValueError(f"{name}: expected a weight >= 0, got {value!r}")
    return value


def check_variance(name: str, value):
    """Raise ValueError naming `name` unless `value` is a finite real variance >= 0; return it."""
    check_scalar(name, value)
    if value < 0:
        raise ValueError(f"{name}: expected a variance >= 0, got {value!r}")
    return value


def check_image_size(shape: tuple, min_size: int, why: str) -> None:
    """Raise ValueError naming `pred` when an image of `shape` (H, W, 3) is smaller than
    `min_size` x `min_size` pixels, which `why` needs."""
    height, width = shape[:2]
    if min(height, width) < min_size:
        raise ValueError(f"pred: {why} needs images of at least {min_size} x {min_size} pixels, "
                         f"got {height} x {width}")


def shape_matches(actual: tuple, expected: Shape) -> bool:
    """Whether the shape `actual` fits the pattern `expected` (see `Shape`)."""
    if expected and expected[0] == "...":
        tail = expected[1:]
        if len(actual) < len(tail):
            return False
        actual = actual[len(actual) - len(tail):]
        expected = tail
    if len(actual) != len(expected):
        return False
    return all(e is None or a == e for a, e in zip(actual, expected))


def format_shape(shape: Shape) -> str:
    """The pattern `shape` as an error message writes it: (N, 3), (..., 12)."""
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
