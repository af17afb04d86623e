"""The D-NeRF/NVFi loader: velogauss/data/dnerf.py."""

import json

import imageio.v3 as iio
import numpy as np
import pytest

from velogauss.data import DataError, load_scene
from velogauss.scenes import make_scene

# Images are stored as 8-bit PNGs and composited in float32: agreement to float32 rounding.
F32 = 1e-6
EIGHT_BIT = 0.5 / 255 + F32  # images are kept as 8 bits (spec/data.md, "Memory"): rounding error


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    """A tiny generated scene: 4 views (view 2 held out), 9 times k/8, 16x16 pixels."""
    return make_scene("toss", tmp_path_factory.mktemp("toss"), resolution=16, n_views=4, n_heldout=1, n_times=9,
                      supersample=2, n_points=100)


def _composite(png_path, background):
    rgba = iio.imread(png_path).astype(np.float64) / 255.0
    return rgba[..., :3] * rgba[..., 3:] + np.asarray(background) * (1.0 - rgba[..., 3:])


def test_generated_scene_splits_by_time(generated):
    scene = load_scene(generated)
    times = np.arange(9) / 8
    observed, future = times[times <= 0.75], times[times > 0.75]
    assert len(scene.train) == 3 * len(observed)
    assert sorted({f.time for f in scene.train}) == pytest.approx(observed)
    assert len(scene.interpolation) == len(observed)  # the held-out view over the observed window
    assert sorted({f.time for f in scene.extrapolation}) == pytest.approx(future)
    assert len(scene.extrapolation) == 4 * len(future)
    held_out = {tuple(f.camera.centre.round(9)) for f in scene.interpolation}
    trained = {tuple(f.camera.centre.round(9)) for f in scene.train}
    assert len(held_out) == 1 and not held_out & trained
    for frame in scene.train + scene.interpolation + scene.extrapolation:
        assert frame.image.shape == (16, 16, 3) and frame.image.dtype == np.float32
        assert (frame.camera.width, frame.camera.height) == (16, 16)


def test_loaded_cameras_look_at_the_scene_centre(generated):
    meta = json.loads((generated / "scene.json").read_text())
    for frame in load_scene(generated).train:
        uv, depth = frame.camera.project(np.zeros((1, 3)))
        # The writer aims every camera at the origin from 4 units: it must project to the
        # image centre, (W/2, H/2) in the pixel-centre convention, in front of the camera.
        np.testing.assert_allclose(uv[0], [8.0, 8.0], atol=1e-9)
        np.testing.assert_allclose(depth[0], meta["generator"]["camera_distance"], atol=1e-9)


@pytest.mark.parametrize("background", [(1.0, 1.0, 1.0), (0.0, 0.0, 0.0), (0.2, 0.5, 0.9)])
def test_rgba_is_composited_over_the_background(generated, background):
    scene = load_scene(generated, background=background)
    frame = scene.extrapolation[3]
    expected = _composite(frame.path, background)
    assert frame.pixels.dtype == np.uint8
    np.testing.assert_allclose(frame.image, expected, atol=EIGHT_BIT)
    alpha = iio.imread(frame.path)[..., 3]
    assert alpha.min() == 0 and alpha.max() == 255  # both object and background pixels were checked


def test_half_res_averages_2x2_blocks_and_halves_intrinsics(generated):
    full = load_scene(generated)
    half = load_scene(generated, half_res=True)
    for a, b in zip(full.train[::5], half.train[::5]):
        blocks = a.image.reshape(8, 2, 8, 2, 3).astype(np.float64).mean(axis=(1, 3))
        # Both are rounded to 8 bits: the full image before averaging, the half after.
        np.testing.assert_allclose(b.image, blocks, atol=2 * EIGHT_BIT)
        expected_K = a.camera.K.copy()
        expected_K[:2] /= 2.0
        np.testing.assert_allclose(b.camera.K, expected_K, atol=1e-12)
        np.testing.assert_allclose(b.camera.viewmat, a.camera.viewmat, atol=0)
        assert (b.camera.width, b.camera.height) == (8, 8)


def test_bounds_points_and_metadata_come_from_the_scene_files(generated):
    scene = load_scene(generated)
    meta = json.loads((generated / "scene.json").read_text())
    np.testing.assert_array_equal(scene.bounds, np.asarray(meta["bounds"]))
    assert scene.metadata["name"] == "toss" and scene.metadata["effects"] == meta["effects"]
    assert scene.points.shape == (100, 3) and scene.point_colors.shape == (100, 3)
    assert np.all(scene.points >= scene.bounds[0] - 1e-5) and np.all(scene.points <= scene.bounds[1] + 1e-5)


def test_other_max_time_moves_the_split_without_duplicates(generated):
    scene = load_scene(generated, max_time=0.9)
    # 0.875 is now observed: the test frames at 0.875 repeat train or val (pose, time) pairs
    # and are not added to the interpolation set again.
    assert max(f.time for f in scene.train) == pytest.approx(0.875)
    assert [f.time for f in scene.extrapolation] == pytest.approx([1.0] * 4)
    keys = [(f.time, f.camera.viewmat.tobytes()) for f in scene.interpolation]
    assert len(keys) == len(set(keys)) == 8
    train_keys = {(f.time, f.camera.viewmat.tobytes()) for f in scene.train}
    assert not train_keys & set(keys)


def test_monocular_generated_layout_loads(tmp_path):
    out = make_scene("spin", tmp_path / "mono", resolution=8, n_views=4, n_heldout=1, n_times=9, supersample=1,
                     n_points=20, layout="monocular")
    scene = load_scene(out)
    times = [f.time for f in scene.train]
    assert times == pytest.approx(np.arange(7) / 8)  # one frame per observed time
    centres = [tuple(f.camera.centre.round(9)) for f in scene.train]
    assert all(a != b for a, b in zip(centres, centres[1:]))  # the camera moves every frame


# --- hand-written datasets: layout variants and bad data -----------------------------------


def _c2w(angle):
    """A Blender camera 4 units from the origin at azimuth `angle`, looking at it (OpenGL axes)."""
    eye = 4.0 * np.array([np.sin(angle), -np.cos(angle), 0.0])
    back = eye / np.linalg.norm(eye)
    right = np.cross([0.0, 0.0, 1.0], back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, up, back], axis=1)
    c2w[:3, 3] = eye
    return c2w


def _write_dataset(root, n_times=5, image_size=(6, 4)):
    """A monocular D-NeRF-style scene: one camera per time, RGBA PNGs named without extension.

    train: times k/4 (k = 0..4); val: one frame at 0.5; test: times 0.5 and 1.0; each split
    has its own cameras.
    """
    w, h = image_size
    rng = np.random.default_rng(1)
    times = {"train": np.linspace(0.0, 1.0, n_times), "val": [0.5], "test": [0.5, 1.0]}
    offsets = {"train": 0.0, "val": 1.0, "test": 2.0}  # every split sees the scene from its own cameras
    for split, split_times in times.items():
        (root / split).mkdir(parents=True, exist_ok=True)
        frames = []
        for k, t in enumerate(split_times):
            rgba = rng.integers(0, 256, size=(h, w, 4), dtype=np.uint8)
            iio.imwrite(root / split / f"r_{k:03d}.png", rgba)
            frames.append({"file_path": f"./{split}/r_{k:03d}", "time": float(t),
                           "transform_matrix": _c2w(0.4 * k + offsets[split]).tolist()})
        (root / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": 0.7, "frames": frames}))
    return root


def _edit_json(root, split, edit):
    file = root / f"transforms_{split}.json"
    meta = json.loads(file.read_text())
    edit(meta)
    file.write_text(json.dumps(meta))


def test_handwritten_monocular_dataset_loads(tmp_path):
    root = _write_dataset(tmp_path)
    scene = load_scene(root)
    assert [f.time for f in scene.train] == [0.0, 0.25, 0.5, 0.75]
    assert [f.time for f in scene.interpolation] == [0.5, 0.5]  # the val frame and the t = 0.5 test frame
    assert [f.time for f in scene.extrapolation] == [1.0]
    assert scene.train[0].image.shape == (4, 6, 3)
    # No scene.json or points3d.ply: bounds are where the cameras look (the origin).
    centre = scene.bounds.mean(axis=0)
    np.testing.assert_allclose(centre, 0.0, atol=1e-9)
    # Half-width: 4 units at tan(0.35).
    np.testing.assert_allclose(scene.bounds[1] - centre, 4.0 * np.tan(0.35), atol=1e-9)
    assert scene.points is None and scene.metadata is None


def test_focal_intrinsics_per_frame_and_jpg_images(tmp_path):
    root = _write_dataset(tmp_path)
    for split in ("train", "val", "test"):
        def edit(meta, split=split):
            del meta["camera_angle_x"]
            meta.update({"fl_x": 7.0, "fl_y": 8.0, "cx": 3.0, "cy": 2.0, "w": 6, "h": 4})
            meta["frames"][0]["fl_x"] = 9.5
        _edit_json(root, split, edit)
    rgb = np.full((4, 6, 3), 200, dtype=np.uint8)
    (root / "train" / "r_001.png").unlink()
    iio.imwrite(root / "train" / "r_001.jpg", rgb)
    scene = load_scene(root)
    np.testing.assert_allclose(scene.train[0].camera.K, [[9.5, 0, 3.0], [0, 8.0, 2.0], [0, 0, 1]])
    np.testing.assert_allclose(scene.train[1].camera.K, [[7.0, 0, 3.0], [0, 8.0, 2.0], [0, 0, 1]])
    # A flat JPEG decodes to (nearly) the flat colour: JPEG is lossy only at edges.
    np.testing.assert_allclose(scene.train[1].image, 200 / 255, atol=2 / 255)


def test_nvfi_per_camera_layout_loads(tmp_path):
    root = _write_dataset(tmp_path)
    for split in ("train", "test"):
        def edit(meta):
            frames = meta.pop("frames")
            meta["data"] = {"cam_a": {"transform_matrix": frames[0]["transform_matrix"],
                                      "frames": [{"file_path": f["file_path"]} for f in frames]}}
        _edit_json(root, split, edit)
    scene = load_scene(root)
    # Without `time`, NVFi's loader uses index / (n - 1) per camera.
    assert [f.time for f in scene.train] == [0.0, 0.25, 0.5, 0.75]
    assert [f.time for f in scene.extrapolation] == [1.0]
    assert len({f.camera.viewmat.tobytes() for f in scene.train}) == 1


def _set(split, index, key, value):
    def edit(meta):
        meta["frames"][index][key] = value
    return split, edit


def _delete(split, index, key):
    def edit(meta):
        del meta["frames"][index][key]
    return split, edit


def _scale_pose(meta):
    pose = np.array(meta["frames"][2]["transform_matrix"])
    pose[:3, :3] *= 2.0
    meta["frames"][2]["transform_matrix"] = pose.tolist()


def _singular_pose(meta):
    pose = np.array(meta["frames"][2]["transform_matrix"])
    pose[:3, 0] = pose[:3, 1]
    meta["frames"][2]["transform_matrix"] = pose.tolist()


JSON_CASES = {
    "missing camera_angle_x": (("train", lambda m: m.pop("camera_angle_x")), "transforms_train.json", "camera_angle_x"),
    "missing file_path": (_delete("test", 1, "file_path"), "transforms_test.json", "frames[1].file_path"),
    "missing transform_matrix": (_delete("val", 0, "transform_matrix"), "transforms_val.json",
                                 "frames[0].transform_matrix"),
    "missing time": (_delete("train", 3, "time"), "transforms_train.json", "frames[3].time"),
    "time above 1": (_set("train", 1, "time", 1.5), "transforms_train.json", "frames[1].time"),
    "time below 0": (_set("test", 0, "time", -0.1), "transforms_test.json", "frames[0].time"),
    "time nan": (_set("train", 1, "time", float("nan")), "transforms_train.json", "frames[1].time"),
    "pose nan": (_set("train", 2, "transform_matrix", [[float("nan")] * 4] * 4), "transforms_train.json",
                 "frames[2].transform_matrix"),
    "pose wrong shape": (_set("train", 2, "transform_matrix", [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
                         "transforms_train.json", "frames[2].transform_matrix"),
    "pose scaled": (("train", _scale_pose), "transforms_train.json", "frames[2].transform_matrix"),
    "pose singular": (("train", _singular_pose), "transforms_train.json", "frames[2].transform_matrix"),
    "image missing": (_set("train", 0, "file_path", "./train/nothing"), "transforms_train.json", "frames[0].file_path"),
    "width mismatch": (("train", lambda m: m.update(w=99)), "transforms_train.json", "w"),
    "bad fov": (("test", lambda m: m.update(camera_angle_x=0.0)), "transforms_test.json", "camera_angle_x"),
    "no frames": (("val", lambda m: m.pop("frames")), "transforms_val.json", "frames"),
    "empty train": (("train", lambda m: [f.update(time=0.9) for f in m["frames"]]), "transforms_train.json", "frames"),
    "empty extrapolation": (("test", lambda m: [f.update(time=0.5) for f in m["frames"]]), "transforms_test.json",
                            "frames"),
}


@pytest.mark.parametrize("case", sorted(JSON_CASES))
def test_bad_transforms_raise_one_data_error_naming_file_and_field(tmp_path, case):
    (split, edit), file, field = JSON_CASES[case]
    root = _write_dataset(tmp_path)
    _edit_json(root, split, edit)
    with pytest.raises(DataError) as info:
        load_scene(root)
    message = str(info.value)
    assert file in message and field in message, message
    assert info.value.field.endswith(field)


def test_empty_split_messages_say_which_and_why(tmp_path):
    root = _write_dataset(tmp_path)
    _edit_json(root, "test", lambda m: [f.update(time=0.5) for f in m["frames"]])
    with pytest.raises(DataError, match=r"empty extrapolation split: no frame with time > max_time=0.75"):
        load_scene(root)
    other = _write_dataset(tmp_path / "other")
    _edit_json(other, "train", lambda m: m["frames"].pop(0))
    expected = r"empty train split: no frame with time <= max_time=0.2 \(4 frames with times in \[0.25, 1\]\)"
    with pytest.raises(DataError, match=expected):
        load_scene(other, max_time=0.2)


def test_missing_transforms_file(tmp_path):
    root = _write_dataset(tmp_path)
    (root / "transforms_test.json").unlink()
    with pytest.raises(DataError, match=r"transforms_test\.json: file: missing"):
        load_scene(root)
    (root / "transforms_val.json").unlink()
    with pytest.raises(DataError, match="transforms_test.json"):  # val is optional, test is not
        load_scene(root)


def test_unreadable_image(tmp_path):
    root = _write_dataset(tmp_path)
    (root / "train" / "r_002.png").write_bytes(b"not a png at all")
    with pytest.raises(DataError, match=r"r_002\.png: file_path: unreadable image"):
        load_scene(root)


def test_images_of_different_sizes(tmp_path):
    root = _write_dataset(tmp_path)
    iio.imwrite(root / "val" / "r_000.png", np.zeros((5, 6, 4), dtype=np.uint8))
    with pytest.raises(DataError, match=r"r_000\.png: file_path: image is 6x5 but .* is 6x4"):
        load_scene(root)


def test_broken_point_cloud_and_scene_json(tmp_path):
    root = _write_dataset(tmp_path)
    (root / "points3d.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n")
    with pytest.raises(DataError, match=r"points3d\.ply: vertex\.y: missing property"):
        load_scene(root)
    (root / "points3d.ply").unlink()
    (root / "scene.json").write_text(json.dumps({"bounds": [[1, 0, 0], [0, 1, 1]]}))
    with pytest.raises(DataError, match=r"scene\.json: bounds: min .* exceeds max"):
        load_scene(root)


@pytest.mark.parametrize(
    "kwargs, name",
    [({"max_time": 1.5}, "max_time"), ({"max_time": 0.0}, "max_time"), ({"max_time": float("nan")}, "max_time"),
     ({"max_time": "0.5"}, "max_time"), ({"background": (1.0, 1.0)}, "background"),
     ({"background": (0.0, 2.0, 0.0)}, "background"), ({"half_res": "yes"}, "half_res")],
)
def test_bad_arguments_raise_naming_them(tmp_path, kwargs, name):
    with pytest.raises(DataError, match=rf"^{name}: "):
        load_scene(tmp_path, **kwargs)
