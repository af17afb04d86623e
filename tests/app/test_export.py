"""Tests of velogauss/export.py: the 3DGS PLY layout, read back by an independent parser, and
the 4D sequence of `velogauss export RUN --times` (issue 39, item 5) on a tiny trained run."""

import gc
import json
import re
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import torch
from plyfile import PlyData
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.export import (GRID_TOLERANCE, MAX_SEQUENCE_FRAMES, export_ply, export_sequence, gaussians_to_table,
                              ply_property_names)
from velogauss_core.constants import TIME_HORIZON
from tests.app.cli_checks import assert_refused

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


# --- the 4D sequence: `velogauss export RUN --times` ------------------------------------------

# The run's observed window ends here (`train --max-time`), so the observed/future flags below
# are known by hand.
MAX_TIME = 0.6


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def snapshot(folder):
    """Every file under `folder` and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A run of 4 iterations on a 16-pixel spin scene with max_time = MAX_TIME (never modified:
    tests copy it); the settings of tests/app/test_failures.py's run."""
    root = tmp_path_factory.mktemp("export")
    made = invoke("make-scene", "spin", "--out", root / "scene", "--resolution", 16, "--views", 3, "--times", 5)
    assert made.exit_code == 0, made.output
    result = invoke("train", root / "scene", "--out", root / "run", "--no-eval", "--iterations", 4,
                    "--max-time", MAX_TIME, "--set", "train.warmup=1", "--set", "train.curriculum=1",
                    "--set", "model.init_points=200", "--set", "physics.n_points=32",
                    "--set", "model.effects=declared", "--set", "model.patterns=rigid")
    assert result.exit_code == 0, result.output
    return root / "run"


@pytest.fixture
def run(trained, tmp_path):
    """A copy of the trained run that a test may write into."""
    return Path(shutil.copytree(trained, tmp_path / "run"))


def test_sequence_files_index_and_frames_equal_the_single_export(run, tmp_path):
    result = invoke("export", run, "--times", "0:1.5:0.05")
    assert result.exit_code == 0, result.output
    folder = run / "sequence"
    # 0, 0.05, ..., 1.5: STOP lands on the grid, so it is a frame: 31 of them.
    times = [k / 20 for k in range(31)]
    names = [f"frame_{k:05d}.ply" for k in range(31)]
    assert sorted(p.name for p in folder.iterdir()) == sorted(names + ["index.json"])
    index = json.loads((folder / "index.json").read_text())
    assert [f["file"] for f in index["frames"]] == names
    assert [f["time"] for f in index["frames"]] == times  # 0.6, not 0.6000000000000001
    # t <= 0.6 is observed: 0 ... 0.6 are the first 13 frames (0.6 itself included), 0.65 ... 1.5 the future.
    assert [f["observed"] for f in index["frames"]] == [True] * 13 + [False] * 18
    assert index["max_time"] == MAX_TIME and index["run"] == str(run.resolve()) and index["complete"] is True
    assert "13 observed, 18 future" in result.output

    for frame in index["frames"]:
        ply = PlyData.read(str(folder / frame["file"]))
        vertex = ply["vertex"]
        assert ply.elements[0].name == "vertex" and len(ply.elements) == 1 and not ply.text
        assert vertex.count == index["gaussians"] > 0
        assert [p.name for p in vertex.properties] == index["ply"]["properties"] == \
            ply_property_names(index["ply"]["sh_degree"])
        single = tmp_path / "single.ply"
        done = invoke("export", run, "--time", repr(frame["time"]), "--out", single)
        assert done.exit_code == 0, done.output
        assert (folder / frame["file"]).read_bytes() == single.read_bytes(), frame


def test_comma_list_and_a_previous_sequence_is_rewritten(run):
    assert invoke("export", run, "--times", "0:1:0.25").exit_code == 0
    assert len(list((run / "sequence").glob("frame_*.ply"))) == 5
    result = invoke("export", run, "--times", "0.5, 1.2")  # the same folder, no --overwrite needed
    assert result.exit_code == 0, result.output
    index = json.loads((run / "sequence" / "index.json").read_text())
    assert [(f["time"], f["file"], f["observed"]) for f in index["frames"]] == \
        [(0.5, "frame_00000.ply", True), (1.2, "frame_00001.ply", False)]
    # The old sequence's frames 2-4 are gone: the folder is exactly the new sequence.
    assert sorted(p.name for p in (run / "sequence").iterdir()) == ["frame_00000.ply", "frame_00001.ply", "index.json"]


def test_out_folder_of_other_files_is_refused_unless_overwrite(run, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    (out / "frame_00000.ply").write_bytes(b"someone else's splat")  # a name the sequence uses
    before = snapshot(out)
    assert_refused(invoke("export", run, "--times", "0,1", "--out", out), "--out", out, "--overwrite")
    assert snapshot(out) == before
    result = invoke("export", run, "--times", "0,1", "--out", out, "--overwrite")
    assert result.exit_code == 0, result.output
    assert (out / "notes.txt").read_text() == "keep me"  # only the sequence's own names are replaced
    assert PlyData.read(str(out / "frame_00000.ply"))["vertex"].count > 0


@pytest.mark.parametrize("spec", [
    "0:1:0", "0:1:-0.1",              # step <= 0
    "1:0:0.1",                         # start > stop
    "0:100:0.001",                     # 100 001 frames, more than MAX_SEQUENCE_FRAMES
    "nan:1:0.1", "0:inf:0.1", "0,nan",  # non-finite
    "-0.5:1:0.1", "-0.5,0",            # times < 0
    "0:1", "0:1:0.1:2", "0:1,2",       # malformed
    "soon", "0,,1", "0,0", "1,0.5",    # not numbers, not increasing
])
def test_bad_times_are_refused_naming_the_flag_and_value(run, spec):
    before = snapshot(run)
    assert_refused(invoke("export", run, "--times", spec), "--times", repr(spec))
    assert snapshot(run) == before and not (run / "sequence").exists()


def test_too_many_frames_names_the_limit(tmp_path):
    spec = f"0:1:{1 / MAX_SEQUENCE_FRAMES}"  # MAX + 1 frames, STOP included
    assert_refused(invoke("export", tmp_path, "--times", spec), "--times", f"{MAX_SEQUENCE_FRAMES + 1} frames",
                   str(MAX_SEQUENCE_FRAMES))


def test_times_help_states_the_grid_rule_and_limits():
    result = invoke("export", "--help")
    assert result.exit_code == 0
    text = " ".join(re.sub("[│╭╮╰╯─]", " ", result.output).split())  # the help column, unwrapped
    # The help's numbers are written out (the CLI does not import torch's modules to read them).
    assert GRID_TOLERANCE == 1e-6
    for rule in ("START:STOP:STEP", "includes STOP", "within 1e-6 of a", f"[0, {TIME_HORIZON:g}]",
                 f"{MAX_SEQUENCE_FRAMES} frames", "RUN_DIR/sequence", "--overwrite"):
        assert rule in text, rule


@pytest.mark.parametrize("args, names", [
    (("--time", "0.5", "--times", "0,1"), ("--time", "--times")),
    ((), ("--time", "--times")),
    (("--time", "0.5", "--overwrite"), ("--overwrite", "--times")),
])
def test_time_and_times_are_exclusive(run, args, names):
    before = snapshot(run)
    assert_refused(invoke("export", run, *args), *names)
    assert snapshot(run) == before


class ManyGaussians(TinyModel):
    """TinyModel's two Gaussians tiled to N = 20 000 (PLY frame: N x 26 float32 = 2.08 MB); each
    call records how many torch tensors are alive."""

    N = 20_000

    def __init__(self):
        super().__init__()
        reps = self.N // 2
        self.means0, self.quats, self.scales = (x.repeat(reps, 1) for x in (self.means0, self.quats, self.scales))
        self.opacities, self.colors = self.opacities.repeat(reps), self.colors.repeat(reps, 1, 1)
        self.live = []

    def render_inputs_at(self, t):
        self.live.append(sum(issubclass(type(o), torch.Tensor) for o in gc.get_objects()))
        return super().render_inputs_at(t)


def test_memory_does_not_grow_with_the_number_of_frames(tmp_path):
    model = ManyGaussians()
    frame_bytes = model.N * len(ply_property_names(1)) * 4
    export_sequence(model, [0.0], tmp_path / "warm", 0.5, tmp_path)  # first-call imports and caches
    peaks, live = {}, {}
    tracemalloc.start()
    try:
        for n in (5, 40):
            model.live = []
            tracemalloc.reset_peak()
            index = export_sequence(model, [k / 10 for k in range(n)], tmp_path / f"seq{n}", 0.5, tmp_path)
            peaks[n] = tracemalloc.get_traced_memory()[1]
            live[n] = model.live
            assert len(index["frames"]) == n and index["gaussians"] == model.N
    finally:
        tracemalloc.stop()
    # Keeping every frame's table or bytes would add at least 35 frames x 2.08 MB = 73 MB from 5 to
    # 40 frames. What legitimately grows is the index: one entry and its JSON text per frame, under
    # 1 KB each, 35 KB in all. One frame's PLY size (2.08 MB) lies 60x above the one and 35x below
    # the other, so it separates them without depending on this machine's allocator.
    assert peaks[40] - peaks[5] < frame_bytes, (peaks, frame_bytes)
    # No tensor of an earlier frame is alive when the next one is computed.
    assert len(set(live[40])) == 1 and live[40][0] == live[5][0], live


def test_an_interrupted_sequence_leaves_an_empty_index_and_can_be_rewritten(tmp_path):
    class Failing(TinyModel):
        def render_inputs_at(self, t):
            if t > 0.25:
                raise KeyboardInterrupt
            return super().render_inputs_at(t)

    out = tmp_path / "seq"
    with pytest.raises(KeyboardInterrupt):
        export_sequence(Failing(), [0.0, 0.25, 0.5, 0.75], out, 0.5, tmp_path)
    index = json.loads((out / "index.json").read_text())
    # The index names no frame that is not written and of its time: none, while incomplete.
    assert index["complete"] is False and index["frames"] == []
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.ply", "frame_00001.ply", "index.json"]
    index = export_sequence(TinyModel(), [0.0, 1.0], out, 0.5, tmp_path)  # a previous sequence: no overwrite
    assert index["complete"] is True and [f["observed"] for f in index["frames"]] == [True, False]
    assert sorted(p.name for p in out.iterdir()) == ["frame_00000.ply", "frame_00001.ply", "index.json"]
