"""Tests of velogauss/io_utils.py: atomic writes never leave half-written or lost results."""

import json
import os
import stat

import imageio.v3 as iio
import numpy as np
import pytest

from velogauss import io_utils


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_writer_raising_midway_keeps_previous_file(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text('{"psnr": 30}')
    with pytest.raises(RuntimeError, match="disk on fire"):
        with io_utils.atomic_path(target) as tmp:
            tmp.write_text('{"psnr": 3')  # half of the new content is already on disk
            raise RuntimeError("disk on fire")
    assert target.read_text() == '{"psnr": 30}'
    assert _leftovers(tmp_path) == []


def test_ctrl_c_midway_keeps_previous_file(tmp_path):
    target = tmp_path / "metrics.md"
    target.write_text("old table\n")
    with pytest.raises(KeyboardInterrupt):
        with io_utils.atomic_path(target) as tmp:
            tmp.write_text("| half")
            raise KeyboardInterrupt
    assert target.read_text() == "old table\n"
    assert _leftovers(tmp_path) == []


def test_png_encoder_failing_keeps_previous_image(tmp_path, monkeypatch):
    target = tmp_path / "frame.png"
    io_utils.write_png(target, np.zeros((4, 5, 3)))
    before = target.read_bytes()

    def broken_imwrite(path, image, **kwargs):
        with open(path, "wb") as handle:
            handle.write(b"\x89PNG half")
        raise OSError("encoder crashed")

    monkeypatch.setattr(iio, "imwrite", broken_imwrite)
    with pytest.raises(OSError, match="encoder crashed"):
        io_utils.write_png(target, np.ones((4, 5, 3)))
    assert target.read_bytes() == before
    assert _leftovers(tmp_path) == []


def test_json_round_trip_with_numpy_values_and_non_finite(tmp_path):
    target = tmp_path / "sub" / "out.json"  # the parent folder is created
    io_utils.write_json(target, {"a": np.float32(1.5), "b": np.arange(3), "c": float("nan"),
                                 "d": [np.inf, np.int64(7)], "e": np.bool_(True), 3: "key"})
    assert json.loads(target.read_text()) == {"a": 1.5, "b": [0, 1, 2], "c": None, "d": [None, 7],
                                              "e": True, "3": "key"}


def test_text_replaces_and_gets_ordinary_permissions(tmp_path):
    target = tmp_path / "table.md"
    io_utils.write_text(target, "first")
    io_utils.write_text(target, "second")
    assert target.read_text() == "second"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~umask


def test_png_round_trip_clips_and_rounds(tmp_path):
    image = np.array([[[-1.0, 0.5, 2.0], [0.0, 1.0, 0.2]]])  # (1, 2, 3)
    io_utils.write_png(tmp_path / "x.png", image)
    back = iio.imread(tmp_path / "x.png")
    # 0.5 * 255 = 127.5 rounds to 128 (round half to even), 0.2 * 255 = 51.
    np.testing.assert_array_equal(back, [[[0, 128, 255], [0, 255, 51]]])


def test_gif_has_every_frame(tmp_path):
    frames = [np.full((6, 8, 3), v) for v in (0.0, 0.5, 1.0)]
    io_utils.write_animation(tmp_path / "seq.gif", frames, fps=4)
    back = iio.imread(tmp_path / "seq.gif", index=None)
    assert back.shape[0] == 3
    np.testing.assert_array_equal(back[..., :3].reshape(3, -1).mean(axis=1), [0, 128, 255])


@pytest.mark.parametrize("bad, match", [({"fps": 0}, "fps"), ({"frames": []}, "frames"),
                                        ({"path": "seq.avi"}, "path")])
def test_animation_bad_input_names_argument(tmp_path, bad, match):
    args = {"path": "seq.gif", "frames": [np.zeros((2, 2, 3))], "fps": 5, **bad}
    with pytest.raises(ValueError, match=match):
        io_utils.write_animation(tmp_path / args["path"], args["frames"], args["fps"])
    assert list(tmp_path.iterdir()) == []
