"""Read and write the `points3d.ply` point clouds used to initialise the Gaussians.

Reads the vertex element of ascii, binary_little_endian and binary_big_endian PLY files:
properties `x, y, z` (required) and `red, green, blue` (optional; integer types are
divided by their maximum, float types are taken as [0, 1]). Other vertex properties
(normals, alpha, ...) are ignored; elements after the vertices (faces) are ignored.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from velogauss.data.errors import DataError

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_ENDIAN = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points `(N, 3)` float64 in world units and optional colours `(N, 3)` float32 in [0, 1]."""

    points: np.ndarray
    colors: np.ndarray | None


def read_ply(path):
    """Read the vertices of a PLY file into a `PointCloud`.

    Raises `DataError` naming the file and the offending header line or property for a
    missing file, an unsupported format, a missing `x`/`y`/`z`, a truncated body or
    non-finite values.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise DataError(path, "file", f"cannot read point cloud ({err.strerror or err})") from None
    fmt, elements, body_start = _parse_header(path, raw)
    names_in_order = [name for name, _, _ in elements]
    if "vertex" not in names_in_order:
        raise DataError(path, "element vertex", "no vertex element in the header")
    before = elements[:names_in_order.index("vertex")]
    _, count, props = elements[len(before)]
    if any(kind == "list" for _, kind in props):
        raise DataError(path, "element vertex", "list properties on vertices are not supported")
    names = [n for n, _ in props]
    for axis in ("x", "y", "z"):
        if axis not in names:
            raise DataError(path, f"vertex.{axis}", "missing property")
    dtype = _row_dtype(fmt, props)
    if fmt == "ascii":
        # Every element instance is one text line, whatever its properties.
        table = _read_ascii(path, raw[body_start:], sum(c for _, c, _ in before), count, dtype)
    else:
        offset = body_start
        for name, rows, element_props in before:
            if any(kind == "list" for _, kind in element_props):
                raise DataError(path, f"element {name}",
                                "binary element with list properties before 'vertex' is not supported")
            offset += rows * _row_dtype(fmt, element_props).itemsize
        if len(raw) < offset + count * dtype.itemsize:
            raise DataError(path, "element vertex", f"file truncated: expected {count} vertices")
        table = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
    points = np.stack([table[a].astype(np.float64) for a in ("x", "y", "z")], axis=-1)
    if not np.all(np.isfinite(points)):
        raise DataError(path, "vertex.x/y/z", "contains non-finite coordinates")
    colors = None
    if all(c in names for c in ("red", "green", "blue")):
        channels = [table[c] for c in ("red", "green", "blue")]
        if channels[0].dtype.kind in "iu":
            colors = np.stack([c.astype(np.float32) / np.iinfo(c.dtype).max for c in channels], axis=-1)
        else:
            colors = np.stack([c.astype(np.float32) for c in channels], axis=-1)
        if not np.all(np.isfinite(colors)):
            raise DataError(path, "vertex.red/green/blue", "contains non-finite colours")
    return PointCloud(points, colors)


def write_ply(path, points, colors=None, normals=None):
    """Write points `(N, 3)` (float32 x, y, z), optional normals `(N, 3)` (nx, ny, nz) and colours
    `(N, 3)` in [0, 1] (uchar red, green, blue) as a binary_little_endian PLY file.

    Raises ValueError naming the argument for a wrong shape or non-finite values.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ValueError(f"points: expected finite (N, 3), got shape {points.shape}")
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    columns = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    for name, array, props in (("normals", normals, ("nx", "ny", "nz")), ("colors", colors, ("red", "green", "blue"))):
        if array is None:
            continue
        array = np.asarray(array, dtype=np.float64)
        if array.shape != points.shape or not np.all(np.isfinite(array)):
            raise ValueError(f"{name}: expected finite {points.shape}, got shape {array.shape}")
        if name == "colors":
            array = np.round(np.clip(array, 0.0, 1.0) * 255.0)
        kind = "u1" if name == "colors" else "<f4"
        for k, prop in enumerate(props):
            fields.append((prop, kind))
            columns[prop] = array[:, k]
    table = np.empty(len(points), dtype=np.dtype(fields))
    for name, _ in fields:
        table[name] = columns[name]
    ply_names = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(points)}"]
    header += [f"property {ply_names[kind]} {name}" for name, kind in fields]
    header.append("end_header")
    Path(path).write_bytes(("\n".join(header) + "\n").encode("ascii") + table.tobytes())


def _row_dtype(fmt, props):
    return np.dtype([(name, _ENDIAN[fmt] + kind) for name, kind in props])


def _parse_header(path, raw):
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise DataError(path, "header", "not a PLY file (missing 'ply' magic or 'end_header')")
    newline = raw.find(b"\n", end)
    body_start = len(raw) if newline < 0 else newline + 1
    fmt = None
    elements = []
    for line in raw[:end].decode("ascii", errors="replace").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _ENDIAN:
                raise DataError(path, "format", f"unsupported PLY format line {line!r}")
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements:
            if words[1] == "list":
                elements[-1][2].append((words[-1], "list"))
            elif len(words) == 3 and words[1] in _PLY_TYPES:
                elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise DataError(path, "property", f"unsupported property line {line!r}")
        else:
            raise DataError(path, "header", f"unexpected header line {line!r}")
    if fmt is None:
        raise DataError(path, "format", "missing format line")
    return fmt, elements, body_start


def _read_ascii(path, body, skip_rows, count, dtype):
    lines = body.decode("ascii", errors="replace").splitlines()[skip_rows:skip_rows + count]
    if len(lines) < count:
        raise DataError(path, "element vertex", f"file truncated: expected {count} vertices, found {len(lines)}")
    table = np.empty(count, dtype=dtype)
    try:
        values = np.array([line.split()[:len(dtype.names)] for line in lines], dtype=np.float64)
    except ValueError:
        raise DataError(path, "element vertex",
                        "malformed vertex line (wrong number of values or not a number)") from None
    if values.shape != (count, len(dtype.names)):
        raise DataError(path, "element vertex", "malformed vertex line (wrong number of values)")
    for k, name in enumerate(dtype.names):
        table[name] = values[:, k]
    return table
