"""How the walkthrough prints: numbers, example sessions, tables, machine-dependent blocks, and
the `Section` each part module returns for one equation ID.

Every number goes through `number`: SIGNIFICANT_DIGITS significant digits, and magnitudes
below ZERO_BELOW printed as 0, so that the text is the same on every machine (different
BLAS kernels and summation orders change the last bits of a result, and the rounding noise
of an exact zero, ~1e-16, changes its sign and digits). Wall-clock times are the one thing
that cannot be made stable: they only appear inside `timings` blocks, which the
regeneration check (tests/app/test_walkthrough.py) strips before comparing.
"""

from typing import NamedTuple

import numpy as np

SIGNIFICANT_DIGITS = 6
# Far above the rounding noise of an exact zero in these small examples (~1e-15) and far
# below every genuinely non-zero value they print (the smallest, integration errors, ~3e-7).
ZERO_BELOW = 1e-12

TIMINGS_START = "<!-- timings:start: machine-dependent, excluded from the regeneration check -->"
TIMINGS_END = "<!-- timings:end -->"


def number(x):
    """One scalar as text: bools and ints as they are, floats to SIGNIFICANT_DIGITS digits."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if abs(x) < ZERO_BELOW:
        return "0"
    return f"{x:.{SIGNIFICANT_DIGITS}g}"


def value(v):
    """A scalar, array or nested list as text; arrays nest their brackets over several lines
    with the entries right-aligned to a common width. Strings pass through unchanged."""
    if isinstance(v, str):
        return v
    a = np.asarray(v)
    if a.ndim == 0:
        return number(a.item())
    cells = [number(x) for x in a.ravel().tolist()]
    width = max((len(c) for c in cells), default=0)
    grid = np.array([c.rjust(width) for c in cells], dtype=object).reshape(a.shape)
    return _nested(grid, 1)


def _nested(grid, indent):
    if grid.ndim == 1:
        return "[" + ", ".join(grid.tolist()) + "]"
    # One line per row; a blank line between the blocks of 3-d and higher arrays.
    separator = ",\n" + "\n" * (grid.ndim > 2) + " " * indent
    return "[" + separator.join(_nested(row, indent + 1) for row in grid) + "]"


def assignments(**named):
    """Lines `name = value`, names padded to one width, continuation lines indented under
    the value's first character."""
    width = max(len(name) for name in named)
    lines = []
    for name, v in named.items():
        prefix = f"{name.ljust(width)} = "
        text = value(v).split("\n")
        lines += [prefix + text[0]] + [" " * len(prefix) + line if line else "" for line in text[1:]]
    return lines


def session(*steps):
    """A fenced text block from steps: a dict of inputs or outputs (printed as assignments),
    or a string (a call, printed as `>>> call`, or a `# comment` kept as it is)."""
    lines = []
    for step in steps:
        if isinstance(step, dict):
            lines += assignments(**step)
        elif step.startswith("#"):
            lines.append(step)
        else:
            lines.append(f">>> {step}")
    return "```text\n" + "\n".join(lines) + "\n```"


def table(header, rows):
    """A Markdown table; cells that are not strings go through `number`."""
    cells = [[c if isinstance(c, str) else number(c) for c in row] for row in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in cells])


def timings(text):
    """Wrap machine-dependent text (wall times) in the markers the regeneration check strips."""
    return f"{TIMINGS_START}\n\n{text}\n\n{TIMINGS_END}"


class Section(NamedTuple):
    """What a part module gives for one equation ID: `intro`, a paragraph on what the equation
    does and why, and `body`, the Markdown blocks that follow the spec text and the reference
    link (example sessions, tables, figures), in order."""

    intro: str
    body: list
