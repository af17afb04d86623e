"""Export the Gaussians of a trained model at one time as a standard 3DGS PLY file.

The layout is the one the original 3D Gaussian Splatting code writes (`GaussianModel.save_ply`)
and that splat viewers (SuperSplat, antimatter15/splat, the SIBR viewer, gsplat's tools)
read: one `vertex` element, `binary_little_endian`, every property `float`, in this order

    x, y, z, nx, ny, nz, f_dc_0, f_dc_1, f_dc_2, f_rest_0 … f_rest_{3((D+1)²−1)−1},
    opacity, scale_0, scale_1, scale_2, rot_0, rot_1, rot_2, rot_3

- normals are zero (3DGS writes zeros too);
- `f_dc_c` is the degree-0 SH coefficient of channel c (VG-SH: `rgb = C0·f_dc + 0.5 + …`);
- `f_rest` is channel-major: all higher-order coefficients of red (SH index 1 … (D+1)²−1),
  then green, then blue — 3DGS stores features `(N, (D+1)²−1, 3)` and writes them
  transposed to `(N, 3, (D+1)²−1)`;
- `opacity` is the logit (viewers apply a sigmoid), `scale_k` the natural log of the
  standard deviation (viewers apply exp), `rot` the normalised quaternion (w, x, y, z).

A 4D sequence (`velogauss export RUN --times ...`, `export_sequence`) is a folder of such
files, one per time, `frame_00000.ply`, `frame_00001.ply`, …, written one at a time by the
same writer as the single export, and `index.json`, which sequence players read: each frame's
time, file and whether it lies in the observed window `t <= max_time` or in the extrapolated
future (spec/conventions.md, "Time"), plus the run, `max_time`, the Gaussian count and the
PLY layout (`sequence_index`).
"""

import json
import math
import re
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from velogauss.data.ply import vertex_ply_bytes
from velogauss.io_utils import check_writable, to_numpy, write_bytes, write_json
from velogauss_fast.quaternion import normalize_quat
from velogauss_fast.sh import C0
from velogauss_core.checks import check_array
from velogauss_core.constants import EXPORT_OPACITY_CLAMP, TIME_HORIZON


def ply_property_names(sh_degree):
    """The vertex property names of a 3DGS PLY of SH degree `sh_degree`, in file order."""
    if isinstance(sh_degree, bool) or not isinstance(sh_degree, (int, np.integer)) or not 0 <= sh_degree <= 3:
        raise ValueError(f"sh_degree: expected an integer in 0..3, got {sh_degree!r}")
    n_rest = 3 * ((sh_degree + 1) ** 2 - 1)
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(n_rest)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def gaussians_to_table(means, quats, scales, opacities, colors, sh_degree):
    """The `(N, P)` float32 table of a 3DGS PLY (columns as `ply_property_names(sh_degree)`).

    `means (N, 3)` world units; `quats (N, 4)` (w, x, y, z), any norm — normalised here by
    `normalize_quat`, a quaternion with `|q|² < QUAT_ZERO_NORM_SQ` is written as the identity
    (spec/conventions.md);
    `scales (N, 3)` standard deviations > 0; `opacities (N,)` in [0, 1], clamped to
    `[EXPORT_OPACITY_CLAMP, 1 − EXPORT_OPACITY_CLAMP]` before the logit so that fully
    transparent or opaque Gaussians stay finite; `colors (N, (D+1)², 3)` SH coefficients
    with `D ≥ sh_degree` (coefficients beyond `sh_degree` are dropped) or `(N, 3)` RGB in
    [0, 1] (converted to the DC coefficient, `(rgb − 0.5) / C0`, with `sh_degree` 0).
    Raises ValueError naming the argument for a wrong shape, a non-finite value, a scale
    ≤ 0 or an opacity outside [0, 1].
    """
    means = _as_f64("means", means, (None, 3))
    n = means.shape[0]
    quats = _as_f64("quats", quats, (n, 4))
    scales = _as_f64("scales", scales, (n, 3))
    opacities = _as_f64("opacities", opacities, (n,))
    colors = _as_f64("colors", colors, None)
    names = ply_property_names(sh_degree)
    if colors.shape == (n, 3):
        if sh_degree != 0:
            raise ValueError(f"colors: RGB colours (N, 3) export with sh_degree 0, got sh_degree={sh_degree}")
        colors = ((colors - 0.5) / C0)[:, None, :]
    n_coeffs = (sh_degree + 1) ** 2
    if colors.ndim != 3 or colors.shape[0] != n or colors.shape[2] != 3 or colors.shape[1] < n_coeffs:
        raise ValueError(f"colors: expected ({n}, >= {n_coeffs}, 3) SH coefficients or ({n}, 3) RGB, got {colors.shape}")
    if np.any(scales <= 0):
        raise ValueError(f"scales: expected standard deviations > 0, found min {scales.min():.3g}")
    if np.any((opacities < 0) | (opacities > 1)):
        raise ValueError(f"opacities: expected values in [0, 1], found [{opacities.min():.3g}, {opacities.max():.3g}]")

    unit = normalize_quat(torch.from_numpy(quats)).numpy()
    clamped = np.clip(opacities, EXPORT_OPACITY_CLAMP, 1.0 - EXPORT_OPACITY_CLAMP)
    logit = np.log(clamped) - np.log1p(-clamped)
    rest = colors[:, 1:n_coeffs, :].transpose(0, 2, 1).reshape(n, -1)  # channel-major, as 3DGS
    table = np.concatenate(
        [means, np.zeros((n, 3)), colors[:, 0, :], rest, logit[:, None], np.log(scales), unit], axis=1
    )
    assert table.shape == (n, len(names)), table.shape
    return table.astype(np.float32)


def ply_bytes(table, sh_degree):
    """The bytes of a binary_little_endian 3DGS PLY holding `table` (as `gaussians_to_table`)."""
    names = ply_property_names(sh_degree)
    table = np.ascontiguousarray(table, dtype="<f4")
    if table.ndim != 2 or table.shape[1] != len(names):
        raise ValueError(f"table: expected (N, {len(names)}) for sh_degree {sh_degree}, got {table.shape}")
    return vertex_ply_bytes(table.view(np.dtype([(name, "<f4") for name in names])).reshape(-1))


def export_ply(model, t, path):
    """Write `model.render_inputs_at(t)` to `path` as a 3DGS PLY (atomically); return the Gaussian count.

    `t`: a finite time (normalised, |t| <= TIME_HORIZON: t > max_time is the extrapolated
    future), evaluated without gradients. Raises ValueError naming `t` for a non-finite,
    non-numeric or too distant time.
    """
    return _write_frame(model, check_time(t), path)[0]


def _write_frame(model, t, path):
    """The one writer of `export_ply` and `export_sequence`: the Gaussians at the checked time
    `t` to `path` (atomically); return `(count N, sh_degree D)`. Everything it builds (the
    Gaussians' tensors, the `(N, P)` table, the PLY bytes) is dropped on return, so a caller
    looping over times holds one frame at a time."""
    with torch.no_grad():  # inference: no graph of the integration steps is kept
        g = model.render_inputs_at(t)
    sh_degree = int(g["sh_degree"])
    table = gaussians_to_table(
        to_numpy(g["means"]), to_numpy(g["quats"]), to_numpy(g["scales"]), to_numpy(g["opacities"]).reshape(-1),
        to_numpy(g["colors"]), sh_degree,
    )
    write_bytes(path, ply_bytes(table, sh_degree))
    return table.shape[0], sh_degree


def check_time(t, name="t"):
    """Return `t` as a float; ValueError naming `name` when it is not a finite real number or
    lies beyond the horizon |t| <= TIME_HORIZON (velogauss_core.constants, where the why is)."""
    try:
        value = float(t)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a finite real number, got {t!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{name}: expected a finite real number, got {t!r}")
    if abs(value) > TIME_HORIZON:
        raise ValueError(f"{name}: {t} is beyond the horizon |t| <= {TIME_HORIZON:g} (TIME_HORIZON: the model has "
                         "seen t in [0, max_time], and integration time grows with |t|)")
    return value


# --- a sequence of times: `velogauss export RUN --times ...` ------------------------------

SEQUENCE_INDEX = "index.json"
# `format` of index.json: marks a folder as this command's sequence (what may be rewritten
# without --overwrite) and tells a reader what it reads; `version` changes with the layout.
SEQUENCE_FORMAT = "velogauss-3dgs-sequence"
SEQUENCE_VERSION = 1
# At most this many frames a sequence: 10 000 frames are 5.5 minutes at 30 frames/s, more than
# any sequence player plays, and already 25 GB of PLY for 10k Gaussians of SH degree 3 (62
# floats each, 2.5 MB a frame). A mistyped STEP (0:100:1e-6, 10^8 frames) is refused at once
# instead of filling the disk.
MAX_SEQUENCE_FRAMES = 10_000
# STOP of START:STOP:STEP is a frame when (STOP − START)/STEP is within this of an integer.
# Decimal steps are not exact binary floats: (1.5 − 0)/0.05 is 30.000000000000004, an error
# near 1e-15 relative, which must not drop the last frame; 1e-6 of a step is far above such
# rounding and far below any time difference a user means (a STOP off the grid by a millionth
# of a step is taken as on it).
GRID_TOLERANCE = 1e-6
# Grid times are rounded to 15 significant digits (every decimal of up to 15 digits survives a
# float64 round trip): START + k·STEP = 0.6000000000000001 is written, and flagged against
# max_time, as the 0.6 the user typed. The change is below 1e-15 relative.
_GRID_DIGITS = 15
_FRAME_FILE = re.compile(r"frame_\d{5}\.ply")
# The temporaries of velogauss.io_utils.atomic_path for the sequence's own files.
_OWN_TEMPORARY = re.compile(r"\.(frame_\d{5}\.ply|index\.json)\..+\.tmp\.(ply|json)")


def frame_file(k):
    """The file name of frame `k` (0-based) of a sequence: `frame_00000.ply` … (zero-padded to
    five digits, more than MAX_SEQUENCE_FRAMES needs, so names sort in frame order)."""
    return f"frame_{k:05d}.ply"


def parse_times(text, name="--times"):
    """The times of a sequence from `text`: a list of floats, strictly increasing, each in
    [0, TIME_HORIZON], at most MAX_SEQUENCE_FRAMES of them.

    `text` is `START:STOP:STEP` — START, START + STEP, … up to STOP, which is included when it
    lands on the grid within GRID_TOLERANCE of a step (so `0:1.5:0.05` gives 31 times, 0 … 1.5;
    grid times rounded to 15 significant digits, `_GRID_DIGITS`) — or a comma list `t1,t2,...`
    (one time alone is a list). Raises ValueError naming `name` and `text` for anything else:
    a missing or non-numeric part, a non-finite value, STEP <= 0, START > STOP, a time < 0 (a
    sequence runs forward from the first observed frame, t = 0, spec/conventions.md "Time") or
    beyond TIME_HORIZON, a list that does not increase, more than MAX_SEQUENCE_FRAMES frames.
    """
    spec = str(text).strip()

    def bad(why):
        return ValueError(f"{name}: {why}; expected START:STOP:STEP or t1,t2,..., got {text!r}")

    def number(part):
        try:
            value = float(part)
        except ValueError:
            raise bad(f"{part.strip()!r} is not a number") from None
        if not math.isfinite(value):
            raise bad(f"{part.strip()} is not a finite time")
        return value

    if ":" in spec:
        if "," in spec:
            raise bad("a range and a list at once")
        parts = spec.split(":")
        if len(parts) != 3:
            raise bad(f"a range has three parts, START:STOP:STEP, not {len(parts)}")
        start, stop, step = (number(part) for part in parts)
        if not step > 0:
            raise bad(f"STEP must be > 0, got {step:g}")
        if start > stop:
            raise bad(f"START {start:g} is after STOP {stop:g}")
        _check_bounds([start, stop], bad)
        q = (stop - start) / step  # steps from START to STOP; inf for a denormal STEP
        if not math.isfinite(q):
            raise bad(_too_many("unboundedly many"))
        on_grid = abs(q - round(q)) <= GRID_TOLERANCE
        steps = round(q) if on_grid else math.floor(q)
        if steps + 1 > MAX_SEQUENCE_FRAMES:  # counted before any list is built
            raise bad(_too_many(steps + 1))
        times = [float(f"{start + k * step:.{_GRID_DIGITS}g}") for k in range(steps + 1)]
        if on_grid:
            times[-1] = stop
        return _check_times(times, bad, step)
    return _check_times([number(part) for part in spec.split(",")], bad)


def check_times(times, name="times"):
    """`times` (numbers) as a list of floats, or ValueError naming `name`: the rules of
    `parse_times` (one to MAX_SEQUENCE_FRAMES times, finite, in [0, TIME_HORIZON], strictly
    increasing), for callers that pass times rather than the flag's text."""
    values = [check_time(t, name) for t in times]

    def bad(why):
        shown = ", ".join(f"{t:g}" for t in values[:5]) + (", ..." if len(values) > 5 else "")
        return ValueError(f"{name}: {why}, got [{shown}]")

    if not values:
        raise bad("expected at least one time")
    return _check_times(values, bad)


def check_sequence_folder(folder, n_frames, overwrite=False, name="--out"):
    """Check, before any work, that a sequence of `n_frames` may be written into `folder`;
    return what it holds: "new" (absent or empty), "previous" (a sequence of this command:
    index.json of SEQUENCE_FORMAT, frame files and their temporaries, nothing else) or, with
    `overwrite`, "other".

    A user's mistake must not destroy files: a non-empty folder that is not a previous
    sequence is refused (ValueError naming `name`, the folder and what it holds) unless
    `overwrite`, and even then only the files of the sequence's own names are replaced.
    OSError when the folder cannot be written or a folder stands where a file goes.
    """
    folder = Path(folder)
    check_writable(folder, SEQUENCE_INDEX, *(frame_file(k) for k in range(n_frames)))
    if not folder.exists():
        return "new"
    entries = sorted(p.name for p in folder.iterdir())
    if not entries:
        return "new"
    if _is_previous_sequence(folder, entries):
        return "previous"
    if overwrite:
        return "other"
    shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
    raise ValueError(f"{name}: {folder} is not empty and holds no sequence of `velogauss export --times` "
                     f"({shown}); choose another {name}, or pass --overwrite to write into it (files of the "
                     "sequence's names are replaced, the others kept)")


def export_sequence(model, times, folder, max_time, run, overwrite=False, progress=False):
    """Write the Gaussians at each of `times` as a 3DGS PLY into `folder`, then index.json;
    return the index (a dict, as `sequence_index`).

    `times`: increasing times in [0, TIME_HORIZON] (`check_times`; `parse_times` reads the
    flag); `max_time`: the end of the run's observed window (frames with t <= max_time are
    "observed", later ones the extrapolated future, spec/conventions.md "Time"); `run`: the
    run folder, recorded in the index. The folder is checked first (`check_sequence_folder`,
    with `overwrite`).

    Memory does not grow with the number of frames: each frame is computed, converted and
    written by the single export's writer (`_write_frame`, an `(N, P)` table at a time) and
    dropped before the next; what accumulates is one small index entry per frame. Every file
    is written atomically; index.json is written first as an empty, incomplete index (it marks
    the folder as this command's, so an interrupted sequence can be rewritten, and names no
    frame yet) and last as the full one, so at no moment does it name a frame that is not
    written or not of its time. Frames of a previous sequence in `folder` beyond the new one
    are removed after the new index is in place.
    """
    times = check_times(times)
    folder = Path(folder)
    max_time = float(max_time)
    state = check_sequence_folder(folder, len(times), overwrite, name="folder")
    old = set(_own_frames(folder)) if state == "previous" else set()
    write_json(folder / SEQUENCE_INDEX, sequence_index(run, max_time, None, None, [], complete=False))
    frames, count, sh_degree = [], None, None
    for k, t in enumerate(tqdm(times, desc="export", unit="frame", disable=not progress, leave=False)):
        n, degree = _write_frame(model, t, folder / frame_file(k))
        if count is not None and (n, degree) != (count, sh_degree):
            raise RuntimeError(f"the model gave {n} Gaussians of SH degree {degree} at t={t:g}, "
                               f"{count} of degree {sh_degree} before: motion never adds or removes Gaussians")
        count, sh_degree = n, degree
        frames.append({"time": t, "file": frame_file(k), "observed": t <= max_time})
    index = sequence_index(run, max_time, count, sh_degree, frames)
    write_json(folder / SEQUENCE_INDEX, index)
    for name in sorted(old - {f["file"] for f in frames}):
        (folder / name).unlink(missing_ok=True)
    if state == "previous":  # temporaries a killed export left behind
        for path in folder.iterdir():
            if _OWN_TEMPORARY.fullmatch(path.name):
                path.unlink(missing_ok=True)
    return index


def sequence_index(run, max_time, gaussians, sh_degree, frames, complete=True):
    """The content of a sequence's index.json (a JSON object):

    - `format` SEQUENCE_FORMAT, `version` SEQUENCE_VERSION, `complete` (false only while the
      frames are being written, when `frames` is empty);
    - `run`: the run folder (absolute), `max_time`: the end of its observed window;
    - `gaussians`: N, the Gaussians in every frame (the same at every time);
    - `ply`: the files' layout, `3dgs` (as `GaussianModel.save_ply`), encoding
      `binary_little_endian`, `sh_degree` D and the vertex `properties` in file order
      (`ply_property_names(D)`);
    - `frames`: in time order, `{"time": t, "file": "frame_00000.ply", "observed": t <= max_time}`,
      `file` relative to the index's folder.
    """
    ply = None if sh_degree is None else {"layout": "3dgs", "encoding": "binary_little_endian", "sh_degree": sh_degree,
                                          "properties": ply_property_names(sh_degree)}
    return {"format": SEQUENCE_FORMAT, "version": SEQUENCE_VERSION, "complete": complete,
            "run": str(Path(run).resolve()), "max_time": max_time, "gaussians": gaussians, "ply": ply,
            "frames": frames}


def _check_times(times, bad, step=None):
    """`times` (finite floats) when they obey the sequence's rules, else the error `bad(why)`;
    `step`: the range's STEP, named when two grid times round to one."""
    if len(times) > MAX_SEQUENCE_FRAMES:
        raise bad(_too_many(len(times)))
    _check_bounds(times, bad)
    for a, b in zip(times, times[1:]):
        if not b > a:
            raise bad(f"times must increase, and {b:g} follows {a:g}" if step is None else
                      f"STEP {step:g} is below the resolution of the times near {a:g}")
    return times


def _check_bounds(times, bad):
    for t in times:
        if t < 0:
            raise bad(f"times must be >= 0 (a sequence runs forward from t = 0), found {t:g}")
        if t > TIME_HORIZON:
            raise bad(f"{t:g} is beyond the horizon t <= {TIME_HORIZON:g} (TIME_HORIZON)")


def _too_many(count):
    return f"{count} frames, more than the {MAX_SEQUENCE_FRAMES} a sequence may have (MAX_SEQUENCE_FRAMES)"


def _own_frames(folder):
    return [p.name for p in folder.iterdir() if _FRAME_FILE.fullmatch(p.name) and p.is_file()]


def _is_previous_sequence(folder, entries):
    """Whether `entries` (the names in `folder`) are a sequence of this command and nothing else."""
    try:
        index = json.loads((folder / SEQUENCE_INDEX).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    if not isinstance(index, dict) or index.get("format") != SEQUENCE_FORMAT:
        return False
    return all(name == SEQUENCE_INDEX or _OWN_TEMPORARY.fullmatch(name)
               or (_FRAME_FILE.fullmatch(name) and (folder / name).is_file()) for name in entries)


def _as_f64(name, x, shape):
    return np.asarray(check_array(name, np.asarray(x, dtype=np.float64), shape), dtype=np.float64)
