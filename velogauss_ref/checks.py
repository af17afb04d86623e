"""Input validation of the reference functions (spec/conventions.md, "Bad input").

`velogauss_core.checks` applied to autograd's traced boxes as well as plain arrays: the
value inside a box is checked, the box itself is returned unchanged.
"""

from autograd.tracer import getval

from velogauss_core import checks


def check_array(name, x, shape=None):
    """Raise ValueError unless `x` (array or autograd box) is finite and matches `shape`
    (`velogauss_core.checks.Shape`); return `x`."""
    checks.check_array(name, getval(x), shape)
    return x


def check_scalar(name, x):
    """Raise ValueError unless `x` (number, 0-d array or autograd box) is a finite real scalar; return `x`."""
    checks.check_scalar(name, getval(x))
    return x
