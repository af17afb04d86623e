"""Atomic writes of the walkthrough's files.

A tiny local twin of velogauss.io_utils.atomic_path: the reference does not depend on the
application package. Each file is written beside its destination and moved over it only
once complete, so an interrupted run never leaves a half-written page or figure.
"""

import contextlib
import os
import tempfile
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path` (same suffix); on a clean exit move it over `path`.

    If the body raises, the temporary file is removed and `path` is left as it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    # mkstemp makes the file private (0600); a page and its figures are meant to be read.
    os.chmod(tmp, 0o644)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
