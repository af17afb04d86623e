"""The nerfstudio `transforms.json` loader (velogauss/data/nerfstudio.py), layout detection
(velogauss/data/__init__.py) and the nerfstudio writer (velogauss/scenes/writer.py).

Expected values come from the generator's own record (scene.json) or are computed by hand,
never from the loader under test; the D-NeRF loader is the reference for "the same scene"."""

import json
import math
import re

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.data import DataError, detect_format, load_scene
from velogauss.data.cameras import look_at
from velogauss.data.nerfstudio import load_scene as load_nerfstudio
from velogauss.run import build_config, load_run_scene, train_flags
from velogauss.scenes import SCENES, make_scene

SIZE = dict(resolution=16, n_views=4, n_heldout=1, n_times=9, supersample=1, n_points=50)


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The same tiny generated scene in both layouts: 4 views (one held out), 9 times k/8, 16x16."""
    root = tmp_path_factory.mktemp("pair")
    return (make_scene("toss", root / "dnerf", **SIZE),
            make_scene("toss", root / "ns", **SIZE, format="nerfstudio"))


def _view_time(frame):
    view, index = re.search(r"r_(\d+)_(\d+)\.png$", frame.path).groups()
    return int(view), int(index)


def _generator_camera(meta, view):
    """The generator's camera `view`: world-to-camera and K, from scene.json's record alone."""
    gen = meta["generator"]
    az, el = math.radians(gen["azimuths_deg"][view]), math.radians(gen["elevations_deg"][view])
    target = np.asarray(SCENES[meta["name"]]().look_at, dtype=np.float64)
    eye = target + gen["camera_distance"] * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az),
                                                      math.sin(el)])
    width, height = gen["resolution"]
    f = 0.5 * width / math.tan(0.5 * gen["camera_angle_x"])
    return look_at(eye, target), np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]])


# --- the generated scene in both layouts -------------------------------------------------

@pytest.mark.parametrize("split", ["time", "future:0.8", "future:0.54"])
def test_both_layouts_load_the_same_scene(pair, split):
    a, b = load_scene(pair[0], split=split), load_scene(pair[1], split=split)
    assert a.max_time == b.max_time
    for part in ("train", "interpolation", "extrapolation"):
        frames_a, frames_b = getattr(a, part), getattr(b, part)
        assert len(frames_a) == len(frames_b)
        assert part == "interpolation" or frames_b
        for x, y in zip(frames_a, frames_b):
            assert _view_time(x) == _view_time(y) and x.time == y.time
            np.testing.assert_allclose(y.camera.viewmat, x.camera.viewmat, atol=1e-6)
            np.testing.assert_allclose(y.camera.K, x.camera.K, atol=1e-6)
            np.testing.assert_array_equal(y.image, x.image)
    np.testing.assert_array_equal(a.bounds, b.bounds)
    np.testing.assert_array_equal(a.points, b.points)


def test_nerfstudio_cameras_times_and_splits_match_the_generator(pair):
    meta = json.loads((pair[1] / "scene.json").read_text())
    heldout = set(meta["generator"]["heldout_views"])
    scene = load_scene(pair[1])
    for frame in scene.train + scene.interpolation + scene.extrapolation:
        view, index = _view_time(frame)
        viewmat, K = _generator_camera(meta, view)
        np.testing.assert_allclose(frame.camera.viewmat, viewmat, atol=1e-6)
        np.testing.assert_allclose(frame.camera.K, K, atol=1e-6)
        assert frame.time == pytest.approx(index / 8, abs=1e-12)
    observed = [k for k in range(9) if k / 8 <= 0.75]
    assert sorted(_view_time(f) for f in scene.train) == [(v, k) for v in range(4) if v not in heldout
                                                          for k in observed]
    assert sorted(_view_time(f) for f in scene.interpolation) == [(v, k) for v in sorted(heldout) for k in observed]
    assert sorted(_view_time(f) for f in scene.extrapolation) == [(v, k) for v in range(4) for k in (7, 8)]


def test_future_split_takes_the_same_frames_as_the_dnerf_layout(pair):
    # future:0.8 of the 27 + 8 = 35 train and test frames trains on round(28.0) = 28 (hand count:
    # 3 train views x 9 times, then the 4 views x 2 future times of the test file).
    a, b = load_scene(pair[0], split="future:0.8"), load_scene(pair[1], split="future:0.8")
    assert len(b.train) == 28 and len(b.extrapolation) == 7 and b.max_time == 0.875
    assert [_view_time(f) for f in b.train] == [_view_time(f) for f in a.train]
    assert [_view_time(f) for f in b.extrapolation] == [_view_time(f) for f in a.extrapolation]


def test_written_transforms_json_is_nerfstudio_shaped(pair):
    doc = json.loads((pair[1] / "transforms.json").read_text())
    assert doc["camera_model"] == "OPENCV" and {"train_filenames", "val_filenames", "test_filenames"} <= set(doc)
    assert not (pair[1] / "transforms_train.json").exists()
    frame = doc["frames"][0]
    assert {"file_path", "transform_matrix", "time", "fl_x", "fl_y", "cx", "cy", "w", "h"} <= set(frame)
    assert frame["file_path"].endswith(".png") and iio.imread(pair[1] / frame["file_path"]).shape == (16, 16, 4)
    # OpenGL camera-to-world: the camera looks down its -z column, at the scene centre (the origin for toss).
    c2w = np.asarray(frame["transform_matrix"])
    centre, forward = c2w[:3, 3], -c2w[:3, 2]
    target = np.asarray(SCENES["toss"]().look_at)
    np.testing.assert_allclose(forward, (target - centre) / np.linalg.norm(target - centre), atol=1e-9)


# --- hand-written nerfstudio datasets ------------------------------------------------------

def _c2w(z):
    """An OpenGL camera-to-world pose at (0, 0, z) looking down -z (at the origin for z > 0)."""
    pose = np.eye(4)
    pose[2, 3] = z
    return pose.tolist()


def _write(root, frames=None, **top):
    """A 4-frame dataset of 6x4 RGB PNGs (frame k filled with 40 k + 20): cameras at z = 4, 4, 5, 5
    (two cameras), times 0, 1/3, 2/3, 1; shared intrinsics at the top level unless `top` changes them."""
    (root / "images").mkdir(parents=True, exist_ok=True)
    if frames is None:
        frames = []
        for k in range(4):
            iio.imwrite(root / "images" / f"f{k}.png", np.full((4, 6, 3), 40 * k + 20, dtype=np.uint8))
            frames.append({"file_path": f"images/f{k}.png", "transform_matrix": _c2w(4.0 + k // 2), "time": k / 3})
    doc = {"camera_model": "OPENCV", "fl_x": 7.0, "fl_y": 8.0, "cx": 3.0, "cy": 2.0, "w": 6, "h": 4,
           "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "frames": frames,
           "train_filenames": ["images/f0.png", "images/f1.png", "images/f3.png"],
           "val_filenames": ["images/f2.png"], "test_filenames": ["images/f3.png"]}
    doc.update(top)
    doc = {k: v for k, v in doc.items() if v is not None}
    (root / "transforms.json").write_text(json.dumps(doc))
    return root


def _edit(root, change):
    doc = json.loads((root / "transforms.json").read_text())
    change(doc)
    (root / "transforms.json").write_text(json.dumps(doc))


def test_hand_written_scene_loads_with_its_lists(tmp_path):
    root = _write(tmp_path / "s")
    scene = load_scene(root, max_time=0.5)
    assert [f.time for f in scene.train] == pytest.approx([0.0, 1 / 3])
    assert [f.time for f in scene.interpolation] == []  # f2 (t = 2/3) is after the window
    assert [f.time for f in scene.extrapolation] == pytest.approx([1.0])
    np.testing.assert_allclose(scene.train[0].image, 20 / 255, atol=1e-7)
    # viewmat = inverse(c2w_gl · diag(1, -1, -1, 1)): the camera at z = 4 maps the origin to depth 4.
    np.testing.assert_allclose(scene.train[0].camera.viewmat,
                               [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 4], [0, 0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(scene.train[0].camera.K, [[7, 0, 3], [0, 8, 2], [0, 0, 1]])


def test_per_frame_intrinsics_override_the_top_level(tmp_path):
    root = _write(tmp_path / "s")

    def change(doc):
        doc["frames"][1].update({"fl_x": 9.5, "cy": 1.5})
    _edit(root, change)
    scene = load_scene(root, max_time=0.5)
    np.testing.assert_allclose(scene.train[0].camera.K, [[7, 0, 3], [0, 8, 2], [0, 0, 1]])
    np.testing.assert_allclose(scene.train[1].camera.K, [[9.5, 0, 3], [0, 8, 1.5], [0, 0, 1]])


def test_intrinsics_only_per_frame(tmp_path):
    root = _write(tmp_path / "s", fl_x=None, fl_y=None, cx=None, cy=None, w=None, h=None)

    def change(doc):
        for k, frame in enumerate(doc["frames"]):
            frame.update({"fl_x": 5.0 + k, "fl_y": 6.0, "cx": 3.0, "cy": 2.0, "w": 6, "h": 4})
    _edit(root, change)
    scene = load_scene(root, max_time=0.5)
    assert [f.camera.K[0, 0] for f in scene.train] == [5.0, 6.0]


def test_mask_makes_pixels_show_the_background(tmp_path):
    root = _write(tmp_path / "s")
    mask = np.zeros((4, 6), dtype=np.uint8)
    mask[:, :3] = 255
    mask[0, 0] = 51  # 0.2
    iio.imwrite(root / "images" / "m0.png", mask)
    _edit(root, lambda doc: doc["frames"][0].update({"mask_path": "images/m0.png"}))
    image = load_scene(root, max_time=0.5, background=(0.0, 0.5, 1.0)).train[0].image
    m = mask.astype(np.float64)[..., None] / 255
    expected = (20 / 255) * m + np.array([0.0, 0.5, 1.0]) * (1 - m)
    np.testing.assert_allclose(image, expected, atol=0.5 / 255 + 1e-6)  # kept as 8 bits (spec/data.md)


def test_times_outside_the_unit_interval_are_normalised(tmp_path):
    root = _write(tmp_path / "s")

    def change(doc):
        for k, frame in enumerate(doc["frames"]):
            frame["time"] = 10.0 + 2.0 * k  # 10, 12, 14, 16 -> 0, 1/3, 2/3, 1
    _edit(root, change)
    scene = load_scene(root, max_time=0.5)
    assert [f.time for f in scene.train] == pytest.approx([0.0, 1 / 3])
    assert [f.time for f in scene.extrapolation] == pytest.approx([1.0])


def test_without_times_the_frame_index_is_scaled(tmp_path):
    root = _write(tmp_path / "s", train_filenames=None, val_filenames=None, test_filenames=None)

    def change(doc):
        for frame in doc["frames"]:
            del frame["time"]
        doc["frames"].reverse()  # file order, not file names: f3 is now frame 0 (t = 0)
    _edit(root, change)
    scene = load_scene(root, max_time=0.5)
    assert {_name(f): f.time for f in scene.train} == pytest.approx({"f3": 0.0, "f2": 1 / 3})
    assert {_name(f): f.time for f in scene.extrapolation} == pytest.approx({"f1": 2 / 3, "f0": 1.0})


def _name(frame):
    return re.search(r"(f\d)\.png$", frame.path).group(1)


def test_without_lists_every_kth_camera_is_held_out(tmp_path):
    root = _write(tmp_path / "s", train_filenames=None, val_filenames=None, test_filenames=None)
    # Two cameras (z = 4: f0, f1; z = 5: f2, f3); heldout_every=2 holds out camera 1.
    scene = load_nerfstudio(root, max_time=0.7, heldout_every=2)
    assert [_name(f) for f in scene.train] == ["f0", "f1"]
    assert [_name(f) for f in scene.interpolation] == ["f2"]
    assert [_name(f) for f in scene.extrapolation] == ["f3"]
    # The default (every 8th camera) holds none of the two out; f3 is still the future.
    scene = load_scene(root, max_time=0.7)
    assert [_name(f) for f in scene.train] == ["f0", "f1", "f2"] and scene.interpolation == []
    # future:0.5 sorts the train cameras' frames (all four here) by time: round(0.5 x 4) = 2 train.
    scene = load_scene(root, split="future:0.5")
    assert [_name(f) for f in scene.train] == ["f0", "f1"] and [_name(f) for f in scene.extrapolation] == ["f2", "f3"]
    assert scene.max_time == pytest.approx(1 / 3) and scene.interpolation == []
    # With camera 1 held out the pool is f0, f1 only: round(0.75 x 2) = 2 leaves no future frame.
    with pytest.raises(DataError, match=r"data\.split.*round\(0\.75 x 2\) = 2"):
        load_nerfstudio(root, split="future:0.75", heldout_every=2)
    with pytest.raises(DataError, match=r"^heldout_every: expected an integer >= 2"):
        load_nerfstudio(root, heldout_every=1)


def test_named_cameras_are_held_out_instead_of_every_kth(tmp_path):
    root = _write(tmp_path / "s", train_filenames=None, val_filenames=None, test_filenames=None)
    # Camera 0 (z = 4: f0, f1) named: it never trains; camera 1 (f2, f3) does, f3 being its future.
    scene = load_scene(root, max_time=0.7, heldout_cameras=[0])
    assert [_name(f) for f in scene.train] == ["f2"]
    assert [_name(f) for f in scene.interpolation] == ["f0", "f1"]
    assert [_name(f) for f in scene.extrapolation] == ["f3"]
    with pytest.raises(DataError, match=r"transforms\.json: frames: .*camera\(s\) \[2\].*cameras are \[0, 1\]"):
        load_scene(root, heldout_cameras=[2])
    with pytest.raises(DataError, match=r"transforms\.json: frames: .*every camera"):
        load_scene(root, heldout_cameras=[0, 1])
    listed = _write(tmp_path / "listed")
    with pytest.raises(DataError, match=r"transforms\.json: train_filenames: the file lists its own split"):
        load_scene(listed, heldout_cameras=[0])


# --- bad input ---------------------------------------------------------------------------

def _missing_image(root):
    (root / "images" / "f1.png").unlink()


def _undecodable(root):
    (root / "images" / "f1.png").write_bytes(b"not a png at all")


BAD = [
    ("missing image", _missing_image, r"transforms\.json: frames\[1\]\.file_path: image 'images/f1\.png' not found"),
    ("undecodable image", _undecodable, r"f1\.png: file_path: unreadable image"),
    ("3x4 matrix", lambda r: _edit(r, lambda d: d["frames"][2].update({"transform_matrix": _c2w(5.0)[:3]})),
     r"transforms\.json: frames\[2\]\.transform_matrix: expected shape \(4, 4\), got \(3, 4\)"),
    ("NaN in matrix", lambda r: (r / "transforms.json").write_text(
        (r / "transforms.json").read_text().replace('"transform_matrix": [[1.0', '"transform_matrix": [[NaN', 1)),
     r"transforms\.json: frames\[0\]\.transform_matrix: contains non-finite values"),
    ("missing intrinsics", lambda r: _edit(r, lambda d: d.pop("fl_y")),
     r"transforms\.json: frames\[0\]\.fl_y: missing key"),
    ("distortion", lambda r: _edit(r, lambda d: d["frames"][3].update({"k1": 0.01})),
     r"transforms\.json: frames\[3\]\.k1: non-zero distortion coefficient 0\.01"),
    ("top-level distortion", lambda r: _edit(r, lambda d: d.update({"p2": -1e-4})),
     r"transforms\.json: p2: non-zero distortion"),
    ("fisheye", lambda r: _edit(r, lambda d: d.update({"camera_model": "OPENCV_FISHEYE"})),
     r"transforms\.json: camera_model: 'OPENCV_FISHEYE' is not supported"),
    ("some times missing", lambda r: _edit(r, lambda d: d["frames"][2].pop("time")),
     r"transforms\.json: frames\[2\]\.time: missing key"),
    ("list names no frame", lambda r: _edit(r, lambda d: d["val_filenames"].append("images/nope.png")),
     r"transforms\.json: val_filenames\[1\]: 'images/nope\.png' is no frame's file_path"),
    ("lists without train", lambda r: _edit(r, lambda d: d.pop("train_filenames")),
     r"transforms\.json: train_filenames: missing key"),
    ("missing mask", lambda r: _edit(r, lambda d: d["frames"][0].update({"mask_path": "images/m.png"})),
     r"transforms\.json: frames\[0\]\.mask_path: image 'images/m\.png' not found"),
    ("image size vs w", lambda r: _edit(r, lambda d: d["frames"][0].update({"w": 8})),
     r"transforms\.json: frames\[0\]\.w: says 8 pixels"),
]


@pytest.mark.parametrize("what, corrupt, message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_names_the_file_and_field(tmp_path, what, corrupt, message):
    root = _write(tmp_path / "s")
    corrupt(root)
    with pytest.raises(DataError, match=message):
        load_scene(root, max_time=0.5)


def test_missing_transforms_json_when_forced(tmp_path, pair):
    with pytest.raises(DataError, match=r"transforms\.json: file: missing"):
        load_scene(pair[0], format="nerfstudio")
    with pytest.raises(DataError, match=r"transforms_train\.json: file: missing"):
        load_scene(pair[1], format="dnerf")


# --- layout detection and --format -------------------------------------------------------

def test_detection_and_forcing(tmp_path, pair):
    assert detect_format(pair[0]) == "dnerf" and detect_format(pair[1]) == "nerfstudio"
    assert len(load_scene(pair[1], format="nerfstudio").train) == len(load_scene(pair[1]).train)
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match=r"no known scene layout.*transforms_train\.json and transforms_test\.json"
                                        r".*transforms\.json"):
        load_scene(tmp_path / "empty")
    both = _write(tmp_path / "both")
    (both / "transforms_train.json").write_text("{}")
    with pytest.raises(DataError, match=r"both: format: .*several layouts"):
        load_scene(both)
    assert len(load_scene(both, format="nerfstudio", max_time=0.5).train) == 2
    with pytest.raises(DataError, match=r"^format: expected one of auto, dnerf, nerfstudio, panoptic, got 'colmap'"):
        load_scene(both, format="colmap")


def test_format_flag_becomes_the_config_key_the_run_loads_with(pair):
    assert train_flags(data_format="nerfstudio") == {"data.format": ("--format", "nerfstudio")}
    cfg = build_config(None, [], train_flags(data_format="nerfstudio"))
    assert cfg.data.format == "nerfstudio"
    assert len(load_run_scene(cfg, pair[1]).train) == 21
    with pytest.raises(DataError, match=r"transforms\.json: file: missing"):
        load_run_scene(cfg, pair[0])
    assert build_config(None, []).data.format == "auto"


def test_cli_make_scene_format_and_bad_train_format(tmp_path):
    runner = CliRunner()
    result = runner.invoke(app, ["make-scene", "spin", "--out", str(tmp_path / "s"), "--resolution", "8", "--views",
                                 "3", "--times", "3", "--format", "nerfstudio"])
    assert result.exit_code == 0, result.output
    assert detect_format(tmp_path / "s") == "nerfstudio"
    result = runner.invoke(app, ["make-scene", "spin", "--out", str(tmp_path / "t"), "--format", "colmap"])
    assert result.exit_code == 2 and "--format" in result.output and "Traceback" not in result.output
    result = runner.invoke(app, ["train", str(tmp_path / "s"), "--out", str(tmp_path / "run"), "--format", "colmap"])
    assert result.exit_code == 2 and "data.format" in result.output and "Traceback" not in result.output
