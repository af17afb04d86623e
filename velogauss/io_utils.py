"""Atomic file writes for every result velogauss produces (metrics, tables, images, PLY).

Each writer goes to a temporary file in the destination's folder and is moved over the
destination with `os.replace` only once it is complete and flushed to disk. `os.replace` is
atomic on POSIX and Windows when both paths are on the same file system (hence the same
folder), so a crash, an exception or Ctrl-C never leaves a half-written result and never
destroys the previous one: readers see either the old file or the new one.
"""

import contextlib
import errno
import json
import os
import tempfile
from pathlib import Path

import numpy as np

# Read once at import: os.umask can only be read by setting it, which is not thread-safe.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside `path`; on a clean exit move it over `path`.

    The temporary name keeps `path`'s suffix (writers such as imageio and matplotlib pick
    the format from it) and starts with a dot, so directory listings and globs for results
    skip it. Parent folders are created. If the body raises (KeyboardInterrupt included)
    the temporary file is removed, `path` is left untouched and the exception propagates.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp creates the file private (0600); results should get the usual permissions.
    os.chmod(tmp, 0o666 & ~_UMASK)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, path)
    except BaseException as err:
        tmp.unlink(missing_ok=True)
        if isinstance(err, OSError):
            # Named after the destination (not the temporary), so the user knows where it failed.
            reason = "no space left on device" if err.errno == errno.ENOSPC else (err.strerror or str(err))
            raise OSError(err.errno, f"{reason} while writing", str(path)) from None
        raise


def check_writable(folder, *names):
    """Raise OSError naming `folder` unless files can be created in it (or, where it does not
    exist yet, in its nearest existing parent, which must be a folder), or naming the file
    `folder / name` for each of `names` that is a folder. Creates nothing that stays: called
    before work starts, so a read-only or misplaced output fails at once."""
    folder = Path(folder)
    for name in names:
        if (folder / name).is_dir():
            raise IsADirectoryError(errno.EISDIR, "cannot write the file: a folder is in the way", str(folder / name))
    existing = next(p for p in (folder, *folder.parents) if p.exists() or p == Path(p.anchor or "."))
    if not existing.is_dir():
        raise OSError(errno.ENOTDIR, "cannot create the output folder: a file is in the way", str(existing))
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as err:
        raise OSError(err.errno, f"output folder is not writable ({err.strerror})", str(folder)) from None


def write_bytes(path, data):
    """Atomically write `data` (bytes) to `path`."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path, text):
    """Atomically write `text` to `path` as UTF-8."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path, obj):
    """Atomically write `obj` as indented JSON (NumPy scalars and arrays become numbers and lists).

    Non-finite floats are written as `null` rather than as the non-standard `NaN`/`Infinity`
    tokens, so every JSON reader can load the file.
    """
    write_text(path, json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n")


def write_png(path, image):
    """Atomically write an `H×W×3` (or `H×W`) image in [0, 1] as an 8-bit PNG; values are clipped."""
    import imageio.v3 as iio

    with atomic_path(path) as tmp:
        iio.imwrite(tmp, to_uint8(image), extension=".png")


def write_animation(path, frames, fps):
    """Atomically write `frames` (a list of `H×W×3` images in [0, 1]) as a looping GIF or an MP4.

    The format follows `path`'s suffix (`.gif` or `.mp4`; MP4 needs `imageio-ffmpeg`).
    `fps` > 0 frames per second. Raises ValueError naming `fps` or `frames` for bad input.
    """
    import imageio.v3 as iio

    if not fps > 0:
        raise ValueError(f"fps: expected a positive number, got {fps!r}")
    if not frames:
        raise ValueError("frames: nothing to write")
    stack = np.stack([to_uint8(f) for f in frames])
    suffix = Path(path).suffix.lower()
    with atomic_path(path) as tmp:
        if suffix == ".gif":
            iio.imwrite(tmp, stack, extension=".gif", duration=1000.0 / fps, loop=0)
        elif suffix == ".mp4":
            # Even sizes: H.264 with yuv420p refuses odd widths or heights.
            h, w = stack.shape[1] // 2 * 2, stack.shape[2] // 2 * 2
            iio.imwrite(tmp, stack[:, :h, :w], extension=".mp4", plugin="FFMPEG", fps=fps, macro_block_size=1)
        else:
            raise ValueError(f"path: expected a .gif or .mp4 file, got {path}")


def save_figure(path, fig, dpi=120):
    """Atomically save a matplotlib figure to `path` (format from the suffix)."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight")


def to_numpy(x):
    """A NumPy array from a torch tensor (detached, moved to the CPU) or any array-like."""
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def to_uint8(image):
    """`image` in [0, 1] (any shape) → uint8 in [0, 255], clipped and rounded; NaN becomes 0."""
    array = np.nan_to_num(to_numpy(image).astype(np.float64), nan=0.0)
    return np.round(np.clip(array, 0.0, 1.0) * 255.0).astype(np.uint8)


def _fsync(path):
    # Flush the new file's content to disk before the rename: on a power loss the rename
    # could otherwise be durable while the data is not, leaving an empty "new" file.
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj
