"""Point-cloud files: velogauss/data/ply.py."""

import numpy as np
import pytest

from velogauss.data import DataError, read_ply, write_ply


def test_ascii_with_colours_extra_properties_and_other_elements(tmp_path):
    text = "\n".join([
        "ply", "format ascii 1.0", "comment made by hand",
        "element camera 1", "property float fov",
        "element vertex 2",
        "property float x", "property float y", "property float z",
        "property float nx", "property float ny", "property float nz",
        "property uchar red", "property uchar green", "property uchar blue",
        "element face 1", "property list uchar int vertex_indices",
        "end_header",
        "0.7",
        "1.5 -2 3 0 0 1 255 0 51",
        "0 0.25 -1 0 1 0 0 255 102",
        "3 0 1 1",
    ])
    (tmp_path / "p.ply").write_text(text + "\n")
    cloud = read_ply(tmp_path / "p.ply")
    np.testing.assert_array_equal(cloud.points, [[1.5, -2.0, 3.0], [0.0, 0.25, -1.0]])
    np.testing.assert_allclose(cloud.colors, [[1.0, 0.0, 0.2], [0.0, 1.0, 0.4]], atol=1e-7)


def test_binary_round_trip(tmp_path, rng):
    points = rng.normal(size=(50, 3)).astype(np.float32).astype(np.float64)
    colors = rng.integers(0, 256, size=(50, 3)) / 255.0
    write_ply(tmp_path / "p.ply", points, colors, normals=rng.normal(size=(50, 3)))
    cloud = read_ply(tmp_path / "p.ply")
    np.testing.assert_array_equal(cloud.points, points)  # float32 values survive exactly
    np.testing.assert_allclose(cloud.colors, colors, atol=1e-7)


def test_big_endian_double_without_colours(tmp_path):
    header = ("ply\nformat binary_big_endian 1.0\nelement vertex 2\n"
              "property double x\nproperty double y\nproperty double z\nend_header\n")
    body = np.array([1.0, 2.0, 3.0, -4.0, 5.5, 6.25], dtype=">f8").tobytes()
    (tmp_path / "p.ply").write_bytes(header.encode() + body)
    cloud = read_ply(tmp_path / "p.ply")
    np.testing.assert_array_equal(cloud.points, [[1.0, 2.0, 3.0], [-4.0, 5.5, 6.25]])
    assert cloud.colors is None


@pytest.mark.parametrize(
    "content, field",
    [
        (b"hello", "header"),
        (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         b"property float z\nend_header\n" + b"\0" * 20, "element vertex"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n", "vertex.z"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
         b"end_header\n1 nan 2\n", "vertex.x/y/z"),
        (b"ply\nformat ascii 1.0\nelement face 0\nend_header\n", "element vertex"),
        (b"ply\nformat weird 1.0\nelement vertex 0\nend_header\n", "format"),
    ],
    ids=["no-magic", "truncated", "no-z", "nan", "no-vertex", "bad-format"],
)
def test_bad_files_raise_data_error_naming_file_and_field(tmp_path, content, field):
    (tmp_path / "p.ply").write_bytes(content)
    with pytest.raises(DataError) as info:
        read_ply(tmp_path / "p.ply")
    assert "p.ply" in str(info.value) and info.value.field == field


def test_missing_file_and_bad_arguments(tmp_path):
    with pytest.raises(DataError, match=r"nope\.ply: file: "):
        read_ply(tmp_path / "nope.ply")
    with pytest.raises(ValueError, match="^points: "):
        write_ply(tmp_path / "p.ply", np.zeros((3, 2)))
    with pytest.raises(ValueError, match="^colors: "):
        write_ply(tmp_path / "p.ply", np.zeros((3, 3)), colors=np.zeros((2, 3)))
