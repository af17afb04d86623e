"""Held-out cameras named by the user (velogauss/data/heldout.py, `data.heldout_cameras`): a Panoptic
capture without `test_meta.json` gets interpolation views, and bad ids are refused naming the field.

Expected frames come from the generator's record (the written meta files: which `cam_id` is where),
never from the loader under test."""

import re

import pytest

from velogauss.data import DataError, load_scene
from velogauss.data.heldout import check_heldout
from velogauss.run import build_config, load_run_scene
from velogauss.scenes import make_scene

# 4 views (view 2 held out by test_meta.json: spread_heldout(4, 1)), 9 times k/8, 16x16.
SIZE = dict(resolution=16, n_views=4, n_heldout=1, n_times=9, supersample=1, n_points=50)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """The tiny scene in the Panoptic layout, with its test_meta.json and without (a capture that has
    no held-out camera), and in the D-NeRF layout."""
    root = tmp_path_factory.mktemp("held")
    full = make_scene("toss", root / "pan", **SIZE, format="panoptic")
    bare = make_scene("toss", root / "bare", **SIZE, format="panoptic")
    (bare / "test_meta.json").unlink()
    return {"full": full, "bare": bare, "dnerf": make_scene("toss", root / "dnerf", **SIZE)}


def _key(frame):
    """(camera, time index) of a Panoptic frame, from its path `ims/<cam>/<frame>.jpg`."""
    match = re.search(r"ims/(\d+)/(\d+)\.jpg$", frame.path)
    return int(match.group(1)), int(match.group(2))


def _cameras(frames):
    return sorted({_key(f)[0] for f in frames})


def test_without_test_meta_there_is_no_interpolation_until_cameras_are_named(scenes):
    assert load_scene(scenes["bare"], max_time=0.5).interpolation == []
    scene = load_scene(scenes["bare"], max_time=0.5, heldout_cameras=[1])
    assert _cameras(scene.train) == [0, 3]
    # t <= 0.5 is time steps 0..4 of camera 1; the future keeps every camera's later frames.
    assert sorted(_key(f) for f in scene.interpolation) == [(1, k) for k in range(5)]
    assert _cameras(scene.extrapolation) == [0, 1, 3]


def test_named_cameras_join_test_meta_and_never_train_under_the_future_split(scenes):
    scene = load_scene(scenes["full"], max_time=0.5, heldout_cameras=[3])
    assert _cameras(scene.train) == [0, 1] and _cameras(scene.interpolation) == [2, 3]
    # future:0.8 pools the one trained camera's 9 frames: round(7.2) = 7, times 0..6 (t = 6/8).
    scene = load_scene(scenes["bare"], split="future:0.8", heldout_cameras=[0, 3])
    assert _cameras(scene.train) == [1] and _cameras(scene.extrapolation) == [1]
    assert len(scene.train) == 7 and scene.max_time == pytest.approx(6 / 8)
    assert sorted(_key(f) for f in scene.interpolation) == [(c, k) for c in (0, 3) for k in range(7)]


def test_the_config_key_reaches_the_loader(scenes):
    cfg = build_config(None, ["data.heldout_cameras=[1]", "data.max_time=0.5"])
    assert cfg.data.heldout_cameras == (1,)
    assert _cameras(load_run_scene(cfg, scenes["bare"]).interpolation) == [1]
    assert build_config(None, []).data.heldout_cameras == "auto"
    with pytest.raises(ValueError, match="heldout_cameras"):
        build_config(None, ["data.heldout_cameras=[-1]"])


@pytest.mark.parametrize("value", ["none", [], [-1], [1, 1], [True], [1.0], 3])
def test_bad_values_name_the_key(value):
    with pytest.raises(DataError, match=r"^data\.heldout_cameras: expected \"auto\" or a non-empty list"):
        check_heldout(value)


def test_bad_ids_name_the_file_field_and_the_cameras_it_has(scenes):
    with pytest.raises(DataError, match=r"train_meta\.json: cam_id: .*camera\(s\) \[2, 7\].*cameras are \[0, 1, 3\]"):
        load_scene(scenes["full"], heldout_cameras=[2, 7])
    with pytest.raises(DataError, match=r"train_meta\.json: cam_id: .*holds out every camera"):
        load_scene(scenes["bare"], heldout_cameras=[0, 1, 3])
    with pytest.raises(DataError, match=r"dnerf: data\.heldout_cameras: a D-NeRF folder has no camera ids"):
        load_scene(scenes["dnerf"], heldout_cameras=[0])
