"""Tests of velogauss/export.py: the 3DGS PLY layout, read back by an independent parser."""

import numpy as np
import pytest
import torch

from velogauss.export import export_ply, gaussians_to_table, ply_property_names

# The property order of 3DGS's GaussianModel.save_ply / construct_list_of_attributes,
# written out by hand for degree 1: 3 * ((1 + 1)^2 - 1) = 9 f_rest entries.
THREEDGS_DEGREE1 = (
    ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    + [f"f_rest_{i}" for i in range(9)]
    + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
)


def read_ply(path):
    """A minimal PLY reader written for the test: header lines, then a NumPy structured read."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode("ascii").splitlines()
    assert lines[0] == "ply"
    assert lines[1] == "format binary_little_endian 1.0"
    element = lines[2].split()
    assert element[:2] == ["element", "vertex"]
    types = {"float": "<f4", "double": "<f8", "uchar": "u1", "int": "<i4"}
    fields = [(ln.split()[2], types[ln.split()[1]]) for ln in lines[3:-1]]
    assert all(ln.startswith("property ") for ln in lines[3:-1]) and lines[-1] == "end_header"
    table = np.frombuffer(raw, dtype=np.dtype(fields), count=int(element[2]), offset=end)
    assert end + table.nbytes == len(raw), "no trailing bytes after the vertices"
    return [name for name, _ in fields], [kind for _, kind in fields], table


class TinyModel:
    """Two hand-made Gaussians moving with constant velocity (1, 0, 0); SH degree 1."""

    def __init__(self):
        self.means0 = torch.tensor([[0.0, 1.0, 2.0], [-1.0, 0.5, 0.25]])
        self.quats = torch.tensor([[2.0, 0.0, 0.0, 0.0], [1.0, 2.0, -2.0, 4.0]])  # not unit
        self.scales = torch.tensor([[0.1, 0.2, 0.3], [1.0, 0.05, 2.0]])
        self.opacities = torch.tensor([0.5, 0.9])
        self.colors = torch.arange(2 * 4 * 3, dtype=torch.float32).reshape(2, 4, 3) / 10.0

    def render_inputs_at(self, t):
        return {"means": self.means0 + torch.tensor([t, 0.0, 0.0]), "quats": self.quats, "scales": self.scales,
                "opacities": self.opacities, "colors": self.colors, "sh_degree": 1}


def test_property_order_matches_3dgs():
    assert ply_property_names(1) == THREEDGS_DEGREE1
    # Degree 3 has 45 f_rest entries, degree 0 none.
    assert [n for n in ply_property_names(3) if n.startswith("f_rest")][-1] == "f_rest_44"
    assert not any(n.startswith("f_rest") for n in ply_property_names(0))


def test_round_trip_of_hand_made_gaussians(tmp_path):
    model = TinyModel()
    path = tmp_path / "out" / "g.ply"
    assert export_ply(model, 0.5, path) == 2
    names, kinds, table = read_ply(path)
    assert names == THREEDGS_DEGREE1
    assert set(kinds) == {"<f4"}
    col = {n: table[n].astype(np.float64) for n in names}
    # Float32 storage: values agree to float32 rounding (relative 6e-8), so 1e-6 absolute
    # on these O(1) values.
    tol = dict(atol=1e-6, rtol=1e-6)
    np.testing.assert_allclose(np.stack([col["x"], col["y"], col["z"]], 1), [[0.5, 1.0, 2.0], [-0.5, 0.5, 0.25]], **tol)
    np.testing.assert_array_equal(np.stack([col["nx"], col["ny"], col["nz"]], 1), 0.0)
    sh = model.colors.numpy().astype(np.float64)
    np.testing.assert_allclose(np.stack([col[f"f_dc_{c}"] for c in range(3)], 1), sh[:, 0, :], **tol)
    # Channel-major: f_rest_0..2 are red's coefficients 1..3, then green's, then blue's.
    for c in range(3):
        for k in range(3):
            np.testing.assert_allclose(col[f"f_rest_{3 * c + k}"], sh[:, 1 + k, c], **tol)
    np.testing.assert_allclose(1.0 / (1.0 + np.exp(-col["opacity"])), [0.5, 0.9], **tol)
    np.testing.assert_allclose(np.exp(np.stack([col[f"scale_{k}"] for k in range(3)], 1)),
                               model.scales.numpy(), **tol)
    np.testing.assert_allclose(np.stack([col[f"rot_{k}"] for k in range(4)], 1),
                               [[1.0, 0.0, 0.0, 0.0], [0.2, 0.4, -0.4, 0.8]], **tol)


def test_extreme_opacities_and_zero_quaternion_stay_finite():
    table = gaussians_to_table(np.zeros((2, 3)), np.zeros((2, 4)), np.ones((2, 3)), np.array([0.0, 1.0]),
                               np.zeros((2, 1, 3)), 0)
    names = ply_property_names(0)
    assert np.all(np.isfinite(table))
    assert table[0, names.index("opacity")] < -15 and table[1, names.index("opacity")] > 15
    np.testing.assert_array_equal(table[:, names.index("rot_0"):], [[1, 0, 0, 0], [1, 0, 0, 0]])


def test_rgb_colours_become_dc_coefficients():
    rgb = np.array([[0.5, 1.0, 0.0]])
    table = gaussians_to_table(np.zeros((1, 3)), [[1, 0, 0, 0]], np.ones((1, 3)), [0.5], rgb, 0)
    names = ply_property_names(0)
    dc = table[0, names.index("f_dc_0"):names.index("f_dc_2") + 1]
    # A viewer computes rgb = 0.5 + C0 * f_dc with C0 = 1 / (2 sqrt(pi)).
    np.testing.assert_allclose(0.5 + dc / (2.0 * np.sqrt(np.pi)), rgb[0], atol=1e-6)


@pytest.mark.parametrize("t", [float("nan"), float("inf"), "soon"])
def test_bad_time_names_t(tmp_path, t):
    with pytest.raises(ValueError, match="^t: "):
        export_ply(TinyModel(), t, tmp_path / "g.ply")
    assert not (tmp_path / "g.ply").exists()


@pytest.mark.parametrize("field, value, match", [
    ("scales", np.array([[0.1, 0.0, 0.3]]), "scales"),
    ("opacities", np.array([1.5]), "opacities"),
    ("means", np.array([[np.nan, 0.0, 0.0]]), "means"),
    ("colors", np.zeros((1, 2, 3)), "colors"),
])
def test_bad_gaussians_name_the_field(field, value, match):
    args = {"means": np.zeros((1, 3)), "quats": np.array([[1.0, 0, 0, 0]]), "scales": np.ones((1, 3)),
            "opacities": np.array([0.5]), "colors": np.zeros((1, 4, 3)), "sh_degree": 1, field: value}
    with pytest.raises(ValueError, match=f"^{match}: "):
        gaussians_to_table(**args)
