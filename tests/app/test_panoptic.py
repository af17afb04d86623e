"""The Dynamic3DGaussians / CMU Panoptic loader (velogauss/data/panoptic.py), its detection
(velogauss/data/__init__.py) and the panoptic writer (velogauss/scenes/writer.py).

Expected values come from the generator's own record (scene.json, the written meta files) or are
computed by hand, never from the loader under test; the D-NeRF loader is the reference for "the same
scene"."""

import json
import re

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.data import DataError, detect_format, load_scene
from velogauss.run import build_config, load_run_scene, train_flags
from velogauss.scenes import make_scene

SIZE = dict(resolution=16, n_views=4, n_heldout=1, n_times=9, supersample=1, n_points=50)
SMALL = dict(resolution=16, n_views=3, n_heldout=1, n_times=3, supersample=1, n_points=20)
# JPEG error bound (8-bit levels). The writer stores the straight RGB at quality 95 without chroma
# subsampling: quality 95 scales libjpeg's quantisation tables by 0.1, so the steps are 1-13 levels and
# each DCT coefficient is off by at most half a step; over a block that is an RMS error of a few levels,
# concentrated at the silhouettes' hard edges (ringing), where single pixels reach ~25 levels on these
# 16x16 renders (measured: max 25, mean 0.3). The mask is written losslessly (PNG), so compositing adds
# no error of its own: |loaded - reference| = m·|jpeg - rgb| <= |jpeg - rgb|.
JPEG_MAX_ERROR = 32 / 255
JPEG_RMS_ERROR = 4 / 255


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The same tiny generated scene in the D-NeRF and Panoptic layouts: 4 views (view 2 held out:
    spread_heldout(4, 1)), 9 times k/8, 16x16."""
    root = tmp_path_factory.mktemp("pair")
    return make_scene("toss", root / "dnerf", **SIZE), make_scene("toss", root / "pan", **SIZE, format="panoptic")


def _key(frame):
    """(view, time index) from the file name: D-NeRF `r_VV_TTT.png`, Panoptic `ims/V/TTTTTT.jpg`."""
    match = re.search(r"r_(\d+)_(\d+)\.png$", frame.path) or re.search(r"ims/(\d+)/(\d+)\.jpg$", frame.path)
    return int(match.group(1)), int(match.group(2))


def _by_key(frames):
    return {_key(f): f for f in frames}


# --- the generated scene in both layouts -------------------------------------------------

def test_written_files_are_the_authors_layout(pair):
    root = pair[1]
    meta = json.loads((root / "train_meta.json").read_text())
    held = json.loads((root / "test_meta.json").read_text())
    assert (meta["w"], meta["h"]) == (16, 16)
    assert len(meta["fn"]) == len(meta["k"]) == len(meta["w2c"]) == len(meta["cam_id"]) == 9
    assert meta["cam_id"][0] == [0, 1, 3] and held["cam_id"][0] == [2]
    assert meta["fn"][4] == ["0/000004.jpg", "1/000004.jpg", "3/000004.jpg"]
    assert np.asarray(meta["k"][0][0]).shape == (3, 3) and np.asarray(meta["w2c"][0][0]).shape == (4, 4)
    assert iio.imread(root / "ims" / "0" / "000004.jpg").shape == (16, 16, 3)
    assert iio.imread(root / "seg" / "0" / "000004.png").shape == (16, 16)
    data = np.load(root / "init_pt_cld.npz")["data"]
    assert data.shape == (50, 7) and np.all(data[:, 6] == 1)
    assert not (root / "points3d.ply").exists() and not (root / "transforms_train.json").exists()


@pytest.mark.parametrize("split", ["time", "future:0.78"])
def test_both_layouts_load_the_same_cameras_times_and_images(pair, split):
    # The D-NeRF scene under "time" (max_time 0.75, scene.json's) is the reference for both splits:
    # future:0.78 of the 27 train-camera frames trains on round(21.06) = 21 = 3 views x times 0..6/8.
    ref = load_scene(pair[0])
    pan = load_scene(pair[1], split=split)
    assert pan.max_time == 0.75
    for part in ("train", "interpolation", "extrapolation"):
        a, b = _by_key(getattr(ref, part)), _by_key(getattr(pan, part))
        if split != "time" and part == "extrapolation":  # held-out views never train, nor are they in the pool
            a = {k: f for k, f in a.items() if k[0] != 2}
        assert sorted(a) == sorted(b) and b
        for key, x in a.items():
            y = b[key]
            assert y.time == x.time == key[1] / 8
            np.testing.assert_allclose(y.camera.viewmat, x.camera.viewmat, atol=1e-6)
            np.testing.assert_allclose(y.camera.K, x.camera.K, atol=1e-6)
            err = np.abs(y.image - x.image)
            assert err.max() <= JPEG_MAX_ERROR and np.sqrt(np.mean(err ** 2)) <= JPEG_RMS_ERROR
    # Hand count: train = views 0, 1, 3 at k = 0..6; interpolation = view 2 at k = 0..6;
    # extrapolation ("time") = every view at k = 7, 8.
    assert sorted(_by_key(pan.train)) == [(v, k) for v in (0, 1, 3) for k in range(7)]
    assert sorted(_by_key(pan.interpolation)) == [(2, k) for k in range(7)]
    views = (0, 1, 2, 3) if split == "time" else (0, 1, 3)
    assert sorted(_by_key(pan.extrapolation)) == [(v, k) for v in views for k in (7, 8)]
    np.testing.assert_array_equal(pan.bounds, ref.bounds)
    # points3d.ply stores float32 xyz and 8-bit colours; the npz keeps float64.
    np.testing.assert_allclose(pan.points, ref.points, atol=1e-6)
    np.testing.assert_allclose(pan.point_colors, ref.point_colors, atol=0.5 / 255 + 1e-6)


def test_cameras_are_the_written_w2c_and_k(pair):
    meta = json.loads((pair[1] / "train_meta.json").read_text())
    scene = load_scene(pair[1])
    for frame in scene.train:
        view, k = _key(frame)
        c = meta["cam_id"][k].index(view)
        np.testing.assert_allclose(frame.camera.viewmat, meta["w2c"][k][c], atol=1e-9)
        np.testing.assert_array_equal(frame.camera.K, meta["k"][k][c])


def test_future_split_takes_the_first_frames_in_time(pair):
    # future:0.8 of 27 frames: round(21.6) = 22 = times 0..6/8 (21) and the first camera (view 0) at 7/8.
    scene = load_scene(pair[1], split="future:0.8")
    assert [_key(f) for f in scene.train] == [(v, k) for k in range(7) for v in (0, 1, 3)] + [(0, 7)]
    assert [_key(f) for f in scene.extrapolation] == [(1, 7), (3, 7), (0, 8), (1, 8), (3, 8)]
    assert scene.max_time == 0.875 and sorted(_by_key(scene.interpolation)) == [(2, k) for k in range(8)]


def test_mask_is_the_alpha_and_without_masks_the_jpeg_is_used_as_is(tmp_path):
    root = make_scene("toss", tmp_path / "s", **SMALL, format="panoptic")
    scene = load_scene(root, background=(0.0, 0.0, 0.0), max_time=0.5)
    frame = _by_key(scene.train)[(0, 0)]
    seg = iio.imread(root / "seg" / "0" / "000000.png")
    assert np.any(seg == 0) and np.any(seg == 255)
    np.testing.assert_array_equal(frame.image[seg == 0], 0.0)  # masked out: exactly the background
    jpeg = iio.imread(root / "ims" / "0" / "000000.jpg").astype(np.float32) / 255
    np.testing.assert_allclose(frame.image[seg == 255], jpeg[seg == 255], atol=1e-6)
    for path in (root / "seg").rglob("*.png"):
        path.unlink()
    frame = _by_key(load_scene(root, background=(0.0, 0.0, 0.0), max_time=0.5).train)[(0, 0)]
    np.testing.assert_allclose(frame.image, jpeg, atol=1e-6)


# --- bad input ---------------------------------------------------------------------------

def _edit(root, name, change):
    doc = json.loads((root / name).read_text())
    change(doc)
    (root / name).write_text(json.dumps(doc))


def _drop_camera(doc, t, c):
    for key in ("k", "w2c", "fn", "cam_id"):
        del doc[key][t][c]


def _set(key, t, c, value, name="train_meta.json"):
    return lambda r: _edit(r, name, lambda d: d[key][t].__setitem__(c, value))


def _nan_in(key, name="train_meta.json"):
    def change(doc):
        doc[key][0][0][0][0] = float("nan")  # json writes NaN, which Python's json reads back
    return lambda r: _edit(r, name, change)


# SMALL: views 0, 1 train (view 2 held out), times 0, 0.5, 1.
BAD = [
    ("missing image", lambda r: (r / "ims" / "1" / "000001.jpg").unlink(),
     r"train_meta\.json: fn\[1\]\[1\]: image 'ims/1/000001\.jpg' not found"),
    ("undecodable jpeg", lambda r: (r / "ims" / "0" / "000002.jpg").write_bytes(b"\xff\xd8 not a jpeg"),
     r"ims/0/000002\.jpg: file_path: unreadable image"),
    ("k of 3x4", _set("k", 0, 1, [[10, 0, 8, 0], [0, 10, 8, 0], [0, 0, 1, 0]]),
     r"train_meta\.json: k\[0\]\[1\]: expected shape \(3, 3\), got \(3, 4\)"),
    ("k with skew", _set("k", 2, 0, [[10, 1, 8], [0, 10, 8], [0, 0, 1]]),
     r"train_meta\.json: k\[2\]\[0\]: expected \[\[fx, 0, cx\]"),
    ("w2c of 3x4", _set("w2c", 2, 0, np.eye(4)[:3].tolist()),
     r"train_meta\.json: w2c\[2\]\[0\]: expected shape \(4, 4\), got \(3, 4\)"),
    ("w2c not rigid", _set("w2c", 1, 1, (2 * np.eye(4) - np.diag([0, 0, 0, 1])).tolist()),
     r"train_meta\.json: w2c\[1\]\[1\]: rotation block is not a rotation"),
    ("NaN in w2c", _nan_in("w2c"), r"train_meta\.json: w2c\[0\]\[0\]: contains non-finite values"),
    ("NaN in k", _nan_in("k", "test_meta.json"), r"test_meta\.json: k\[0\]\[0\]: contains non-finite values"),
    ("camera count changes", lambda r: _edit(r, "train_meta.json", lambda d: _drop_camera(d, 1, 0)),
     r"train_meta\.json: k\[1\]: has 1 cameras but k\[0\] has 2"),
    ("one list short", lambda r: _edit(r, "train_meta.json", lambda d: d["fn"][2].pop()),
     r"train_meta\.json: fn\[2\]: has 1 cameras but k\[0\] has 2"),
    ("time steps differ", lambda r: _edit(r, "train_meta.json", lambda d: d["cam_id"].pop()),
     r"train_meta\.json: cam_id: has 2 time steps but fn has 3"),
    ("test meta steps differ", lambda r: _edit(r, "test_meta.json", lambda d: [d[k].pop() for k in
                                                                                ("k", "w2c", "fn", "cam_id")]),
     r"test_meta\.json: fn: has 2 time steps but train_meta\.json has 3"),
    ("missing w", lambda r: _edit(r, "train_meta.json", lambda d: d.pop("w")), r"train_meta\.json: w: missing key"),
    ("w vs image", lambda r: _edit(r, "train_meta.json", lambda d: d.update(w=8)),
     r"train_meta\.json: w: says 8 pixels"),
    ("bad point cloud", lambda r: np.savez(r / "init_pt_cld.npz", data=np.zeros((4, 6))),
     r"init_pt_cld\.npz: data: expected a numeric \(N, 7\) array"),
]


@pytest.mark.parametrize("what, corrupt, message", BAD, ids=[b[0] for b in BAD])
def test_bad_input_names_the_file_and_field(tmp_path, what, corrupt, message):
    root = make_scene("toss", tmp_path / "s", **SMALL, format="panoptic")
    load_scene(root, max_time=0.5)  # the scene is fine before the corruption
    corrupt(root)
    with pytest.raises(DataError, match=message):
        load_scene(root, max_time=0.5)


# --- layout detection and --format -------------------------------------------------------

def test_detection_and_forcing(tmp_path, pair):
    assert detect_format(pair[1]) == "panoptic" and detect_format(pair[0]) == "dnerf"
    assert len(load_scene(pair[1], format="panoptic").train) == 21
    with pytest.raises(DataError, match=r"train_meta\.json: file: missing"):
        load_scene(pair[0], format="panoptic")
    with pytest.raises(DataError, match=r"transforms_train\.json: file: missing"):
        load_scene(pair[1], format="dnerf")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DataError, match=r"no known scene layout.*panoptic: train_meta\.json"):
        load_scene(tmp_path / "empty")
    both = make_scene("toss", tmp_path / "both", **SMALL, format="panoptic")
    (both / "transforms.json").write_text("{}")
    with pytest.raises(DataError, match=r"both: format: .*several layouts"):
        load_scene(both)
    assert len(load_scene(both, format="panoptic", max_time=0.5).train) == 4


def test_format_flag_and_make_scene_cli(tmp_path, pair):
    cfg = build_config(None, [], train_flags(data_format="panoptic"))
    assert cfg.data.format == "panoptic" and len(load_run_scene(cfg, pair[1]).train) == 21
    runner = CliRunner()
    result = runner.invoke(app, ["make-scene", "spin", "--out", str(tmp_path / "s"), "--resolution", "8", "--views",
                                 "3", "--times", "3", "--format", "panoptic"])
    assert result.exit_code == 0, result.output
    assert detect_format(tmp_path / "s") == "panoptic"
    assert json.loads((tmp_path / "s" / "scene.json").read_text())["generator"]["format"] == "panoptic"

