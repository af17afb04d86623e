"""How a command reports bad input: one line `error: <what is wrong>` on stderr and exit code 2.

Bad input is a missing run folder, checkpoint or image, a malformed scene file, an unknown
`--set` key, a bad value, a device this machine lacks, an output folder that cannot be written
or a full disk. Only the command-line boundary catches these errors (`DataError`, `ValueError`,
`OSError`), with `user_errors`; anything else is a bug and keeps its traceback.
"""

import contextlib

import typer

from velogauss.data import DataError

EXIT_BAD_INPUT = 2


@contextlib.contextmanager
def user_errors():
    """Turn bad-input exceptions into one `error: ...` line on stderr and exit code 2."""
    try:
        yield
    except OSError as err:  # FileNotFoundError, a read-only or full disk: name the path
        where = f": {err.filename}" if err.filename else ""
        fail(f"{err.strerror or err}{where}")
    except (DataError, ValueError) as err:
        fail(str(err))


def fail(message):
    """Print `error: message` on stderr and exit with code 2."""
    typer.secho(f"error: {message}", err=True, fg=typer.colors.RED)
    raise typer.Exit(EXIT_BAD_INPUT)
