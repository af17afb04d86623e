"""Read and write the `points3d.ply` point clouds used to initialise the Gaussians, with `plyfile`.

Reads the vertex element of ascii, binary_little_endian and binary_big_endian PLY files:
properties `x, y, z` (required) and `red, green, blue` (optional; integer types are
divided by their maximum, float types are taken as [0, 1]). Other vertex properties
(normals, alpha, ...) and other elements (faces, cameras) are ignored.
"""

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement, PlyElementParseError, PlyHeaderParseError

from velogauss.data.errors import DataError
from velogauss.io_utils import write_bytes


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points `(N, 3)` float64 in world units and optional colours `(N, 3)` float32 in [0, 1]."""

    points: np.ndarray
    colors: np.ndarray | None


def read_ply(path: str | Path) -> PointCloud:
    """Read the vertices of a PLY file into a `PointCloud`.

    Raises `DataError` naming the file and the offending header line or property for a
    missing file, an unsupported format, a missing `x`/`y`/`z`, a truncated body or
    non-finite values.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(path, "file", "cannot read point cloud (no such file)")
    try:
        data = PlyData.read(str(path))
    except PlyHeaderParseError as err:
        field = "format" if "format" in err.message else "header"
        raise DataError(path, field, f"line {err.line}: {err.message}") from None
    except PlyElementParseError as err:
        where = f"element {err.element.name}" if err.element is not None else "body"
        raise DataError(path, where, str(err)) from None
    except (OSError, ValueError) as err:
        raise DataError(path, "file", f"cannot read point cloud ({err})") from None
    if "vertex" not in data:
        raise DataError(path, "element vertex", "no vertex element in the header")
    table = data["vertex"].data
    names = table.dtype.names or ()
    for axis in ("x", "y", "z"):
        if axis not in names:
            raise DataError(path, f"vertex.{axis}", "missing property")
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


def write_ply(path: str | Path, points, colors=None, normals=None) -> None:
    """Write points `(N, 3)` (float32 x, y, z), optional normals `(N, 3)` (nx, ny, nz) and colours
    `(N, 3)` in [0, 1] (uchar red, green, blue) as a binary_little_endian PLY file.

    Raises ValueError naming the argument for a wrong shape or non-finite values.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise ValueError(f"points: expected finite (N, 3), got shape {points.shape}")
    columns = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
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
    write_bytes(path, vertex_ply_bytes(table))


def vertex_ply_bytes(table: np.ndarray) -> bytes:
    """A binary_little_endian PLY file holding one vertex element: the structured array
    `table` (N,), one property per field, in field order. `write_ply` and the 3DGS export
    (velogauss.export) both write through here."""
    stream = io.BytesIO()
    PlyData([PlyElement.describe(table, "vertex")], text=False, byte_order="<").write(stream)
    return stream.getvalue()
