"""data.split: the "time" split, ODE-GS's "future:F" protocol and D-NeRF's standard "all"
(spec/data.md, "Splits")."""

import json
import tomllib

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss.config import load_config, to_toml
from velogauss.data import DataError, load_scene
from velogauss.scenes import make_scene

# Times of each file's frames, in file order (unsorted on purpose). 8 train + 5 test frames:
# n = 13; train/r_005 (0.6) and test/r_001 (0.6) tie.
TIMES = {"train": [0.2, 0.0, 0.1, 0.4, 0.3, 0.6, 0.5, 0.7],
         "test": [0.9, 0.6, 0.85, 1.0, 0.65],
         "val": [0.05, 0.7, 0.75, 0.95]}


def _write_scene(root, times=TIMES):
    """A D-NeRF-layout scene of 8x8 RGBA frames at `times`, each frame from its own camera."""
    rng = np.random.default_rng(0)
    for k_split, (split, split_times) in enumerate(times.items()):
        (root / split).mkdir(parents=True, exist_ok=True)
        frames = []
        for k, t in enumerate(split_times):
            iio.imwrite(root / split / f"r_{k:03d}.png", rng.integers(0, 256, size=(8, 8, 4), dtype=np.uint8))
            angle = 0.3 * k + 2.0 * k_split
            eye = 4.0 * np.array([np.sin(angle), -np.cos(angle), 0.0])
            back = eye / 4.0
            right = np.cross([0.0, 0.0, 1.0], back)
            right /= np.linalg.norm(right)
            c2w = np.eye(4)
            c2w[:3, :3] = np.stack([right, np.cross(back, right), back], axis=1)
            c2w[:3, 3] = eye
            frames.append({"file_path": f"./{split}/r_{k:03d}", "time": t, "transform_matrix": c2w.tolist()})
        (root / f"transforms_{split}.json").write_text(json.dumps({"camera_angle_x": 0.7, "frames": frames}))
    return root


def _names(frames):
    """`split/r_00k` of each frame, in order."""
    return [f"{f.path.split('/')[-2]}/{f.path.split('/')[-1][:5]}" for f in frames]


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    return _write_scene(tmp_path_factory.mktemp("split"))


def test_future_split_trains_on_the_first_fraction_by_time(scene_dir):
    scene = load_scene(scene_dir, split="future:0.8")
    # round(0.8 * 13) = round(10.4) = 10 frames by time: 0, .1, .2, .3, .4, .5, .6 (train), .6 (test), .65, .7.
    assert _names(scene.train) == ["train/r_001", "train/r_002", "train/r_000", "train/r_004", "train/r_003",
                                   "train/r_006", "train/r_005", "test/r_001", "test/r_004", "train/r_007"]
    assert [f.time for f in scene.train] == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.6, 0.65, 0.7]
    assert _names(scene.extrapolation) == ["test/r_002", "test/r_000", "test/r_003"]  # 0.85, 0.9, 1.0
    assert scene.max_time == 0.7 and scene.split == "future:0.8"
    # Interpolation: the val frames with t <= 0.7, the end included; no test frame.
    assert _names(scene.interpolation) == ["val/r_000", "val/r_001"]


def test_a_tie_at_the_cut_puts_the_train_file_first(scene_dir):
    # round(0.54 * 13) = round(7.02) = 7: the cut falls between the two frames at t = 0.6.
    scene = load_scene(scene_dir, split="future:0.54")
    assert _names(scene.train)[-1] == "train/r_005" and len(scene.train) == 7
    assert _names(scene.extrapolation) == ["test/r_001", "test/r_004", "train/r_007", "test/r_002", "test/r_000",
                                           "test/r_003"]
    assert scene.max_time == 0.6 and scene.extrapolation[0].time == 0.6
    assert _names(scene.interpolation) == ["val/r_000"]


def test_rounding_is_pythons_half_to_even(scene_dir):
    # 0.5 * 13 = 6.5 exactly, rounded to 6 (half up would give 7).
    scene = load_scene(scene_dir, split="future:0.5")
    assert len(scene.train) == 6 and len(scene.extrapolation) == 7
    assert scene.max_time == 0.5


def test_time_split_is_unchanged(scene_dir):
    for scene in (load_scene(scene_dir), load_scene(scene_dir, max_time=0.75, split="time")):
        assert scene.max_time == 0.75 and scene.split == "time"
        assert _names(scene.train) == [f"train/r_{k:03d}" for k in range(8)]  # file order, all t <= 0.75
        assert _names(scene.extrapolation) == ["test/r_000", "test/r_002", "test/r_003"]
        assert _names(scene.interpolation) == ["val/r_000", "val/r_001", "val/r_002", "test/r_001", "test/r_004"]


def test_max_time_is_derived_and_may_only_repeat_the_derived_value(scene_dir):
    assert load_scene(scene_dir, max_time=0.75, split="future:0.8").max_time == 0.7  # the default: not given
    assert load_scene(scene_dir, max_time=0.7, split="future:0.8").max_time == 0.7  # what config.toml records
    with pytest.raises(DataError, match=r"data\.max_time: 0\.6 disagrees with data\.split 'future:0\.8'.* t = 0\.7"):
        load_scene(scene_dir, max_time=0.6, split="future:0.8")


def test_all_split_trains_every_train_frame_and_scores_the_test_frames(scene_dir):
    scene = load_scene(scene_dir, split="all")
    assert _names(scene.train) == [f"train/r_{k:03d}" for k in range(8)]  # file order
    assert scene.extrapolation == [] and scene.split == "all"
    assert scene.max_time == 0.7  # the last train frame's time (train/r_007)
    # Every val frame, then every test frame (none repeats a train or val view here), at any time.
    assert _names(scene.interpolation) == ["val/r_000", "val/r_001", "val/r_002", "val/r_003"] + [
        f"test/r_{k:03d}" for k in range(5)]
    assert load_scene(scene_dir, max_time=0.7, split="all").max_time == 0.7  # what config.toml records
    with pytest.raises(DataError, match=r"data\.max_time: 0\.6 disagrees with data\.split 'all'.* t = 0\.7"):
        load_scene(scene_dir, max_time=0.6, split="all")


def test_all_split_leaves_out_test_frames_that_repeat_a_train_view(tmp_path):
    root = _write_scene(tmp_path, {"train": [0.0, 0.5, 1.0], "test": [0.5, 0.25]})
    record = json.loads((root / "transforms_train.json").read_text())["frames"][1]
    test = json.loads((root / "transforms_test.json").read_text())
    test["frames"][0]["transform_matrix"] = record["transform_matrix"]  # the train view at t = 0.5 again
    (root / "transforms_test.json").write_text(json.dumps(test))
    scene = load_scene(root, split="all")
    assert _names(scene.interpolation) == ["test/r_001"] and scene.max_time == 1.0


def test_a_window_that_ends_at_one_leaves_the_time_split_no_future(scene_dir):
    with pytest.raises(DataError, match=r"empty extrapolation split: no frame with time > max_time=1\.0"):
        load_scene(scene_dir, max_time=1.0)


@pytest.mark.parametrize("split, message", [
    ("future:0.01", r"data\.split: 'future:0\.01' trains on round\(0\.01 x 13\) = 0 of the 13 .* no train frame"),
    ("future:0.99", r"data\.split: 'future:0\.99' trains on round\(0\.99 x 13\) = 13 of the 13 .* no future frame"),
    # round(1.3) = 1: only the frame at t = 0, an empty observed window.
    ("future:0.1", r"data\.split: 'future:0\.1' trains on round\(0\.1 x 13\) = 1 .* t = 0, .* inside \(0, 1\)"),
])
def test_a_fraction_that_empties_a_side_is_named(scene_dir, split, message):
    with pytest.raises(DataError, match=message):
        load_scene(scene_dir, split=split)


@pytest.mark.parametrize("split", ["futur:0.8", "future:", "future:1.5", "future:1", "future:0", "future:0.0",
                                   "future:-0.5", "future:8e-1", "Time", "All", 0.8])
def test_bad_split_values_are_named(scene_dir, split):
    with pytest.raises(DataError, match=r"^split: expected \"time\", \"all\" or \"future:F\""):
        load_scene(scene_dir, split=split)
    with pytest.raises(ValueError, match=r"^--set: data\.split: "):
        load_config(None, [f"data.split={json.dumps(split)}"])


def test_config_accepts_and_records_the_split(tmp_path):
    assert load_config().data.split == "time"
    for value in ("time", "all", "future:0.8", "future:.75", "future:0.80"):
        cfg = load_config(None, [f"data.split={value}"])  # a bare word, as `--set` passes it
        assert cfg.data.split == value
        path = tmp_path / "c.toml"
        path.write_text(to_toml(cfg))
        assert load_config(path) == cfg


def test_train_then_eval_under_a_future_split(tmp_path):
    """The user's path: a monocular scene without val frames, trained and scored under future:0.75."""
    data = make_scene("spin", tmp_path / "mono", resolution=16, n_views=3, n_heldout=1, n_times=9, supersample=1,
                      n_points=50, layout="monocular")
    (data / "transforms_val.json").unlink()  # no val frames: an empty interpolation split
    run = tmp_path / "run"
    tiny = ["data.split=future:0.75", "train.iterations=6", "train.warmup=1", "train.curriculum=2",
            "train.eval_every=3", "train.checkpoint_every=0", "densify.start=1", "densify.every=2",
            "densify.until=4", "physics.n_points=16", "physics.ramp=2", "train.adf_start=2", "model.hidden=8",
            "model.depth=1", "model.n_patterns=2", "model.code_dim=2", "train.views=1", "train.threads=1"]
    runner = CliRunner()
    args = ["train", str(data), "--out", str(run), "--no-eval"] + [a for s in tiny for a in ("--set", s)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    # 9 train frames (t = k/8) and 6 test frames (3 views at 7/8 and 1): round(0.75 * 15) = 11 trained,
    # the 7 train frames up to 6/8, then at 7/8 the train frame and the 3 test frames.
    assert "(11 train frames)" in result.output
    saved = tomllib.loads((run / "config.toml").read_text())["data"]
    assert saved["split"] == "future:0.75" and saved["max_time"] == 0.875
    # --resume reads config.toml back: the recorded split and window end agree with the data.
    result = runner.invoke(app, ["train", "--out", str(run), "--resume", "--iterations", "8", "--no-eval"])
    assert result.exit_code == 0, result.output

    result = runner.invoke(app, ["eval", str(run)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["split"] == "future:0.75" and metrics["max_time"] == 0.875
    assert metrics["splits"]["extrapolation"]["count"] == 4  # t = 1: the train frame and the 3 test frames
    assert np.isfinite(metrics["splits"]["extrapolation"]["mean"]["psnr"])
    assert np.isfinite(metrics["freeze_baseline"]["mean"]["psnr"])
    interp = metrics["splits"]["interpolation"]
    assert interp["count"] == 0 and interp["frames"] == [] and interp["mean"]["psnr"] is None
    assert "interpolation (t ≤ 0.875): no frames in this split | 0 | — |" in result.output


def test_train_then_eval_under_the_all_split(tmp_path):
    """D-NeRF's standard protocol: every train frame trains, the held-out views score, no future."""
    data = make_scene("spin", tmp_path / "mono", resolution=16, n_views=3, n_heldout=1, n_times=9, supersample=1,
                      n_points=50, layout="monocular")
    run = tmp_path / "run"
    tiny = ["data.split=all", "train.iterations=4", "train.warmup=1", "train.curriculum=2", "train.eval_every=2",
            "train.checkpoint_every=0", "densify.start=1", "densify.every=2", "densify.until=3",
            "physics.n_points=16", "physics.ramp=2", "train.adf_start=2", "model.hidden=8", "model.depth=1",
            "model.n_patterns=2", "model.code_dim=2", "train.views=1", "train.threads=1", "model.patterns=mlp"]
    runner = CliRunner()
    result = runner.invoke(app, ["train", str(data), "--out", str(run)] + [a for s in tiny for a in ("--set", s)])
    assert result.exit_code == 0, result.output
    scene = load_scene(data, split="all")
    assert f"({len(scene.train)} train frames)" in result.output
    saved = tomllib.loads((run / "config.toml").read_text())["data"]
    assert saved["split"] == "all" and saved["max_time"] == scene.max_time == 1.0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["splits"]["interpolation"]["count"] == len(scene.interpolation) > 0
    assert np.isfinite(metrics["splits"]["interpolation"]["mean"]["psnr"])
    assert metrics["splits"]["extrapolation"]["count"] == 0 and metrics["freeze_baseline"]["count"] == 0
    assert 'extrapolation (none: data.split "all" observes the whole clip)' in result.output
    assert "last observed frame frozen" not in result.output
