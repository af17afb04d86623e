"""Load a dynamic scene in nerfstudio's `transforms.json` layout, validated in full before training.

The layout is nerfstudio's (docs/quickstart/data_conventions.md and
nerfstudio/data/dataparsers/nerfstudio_dataparser.py of nerfstudio-project/nerfstudio), with a
per-frame `time` for dynamic scenes. Paths are relative to the scene folder:

- `transforms.json`: pinhole intrinsics `fl_x, fl_y, cx, cy` (pixels; required) and optional `w, h`,
  at the top level or per frame (a frame's value wins); `camera_model` absent, "OPENCV", "PINHOLE"
  or "SIMPLE_PINHOLE"; distortion `k1, k2, k3, k4, p1, p2` (top level or per frame) absent or 0 --
  a non-zero one is refused (velogauss renders ideal pinholes: undistort the images first).
  `frames: [{file_path, transform_matrix, time?, mask_path?, ...}]`: `transform_matrix` is 4x4
  camera-to-world with OpenGL/Blender axes (+x right, +y up, +z back), converted once at load as
  D-NeRF's (spec/conventions.md, "Cameras"); no auto-orientation, centring or scaling is applied
  (nerfstudio's `ns-train` does them; `applied_transform`, `orientation_override` are ignored).
  Optional `train_filenames`, `val_filenames`, `test_filenames` (lists of `file_path`s), and
  `ply_file_path` (the initial point cloud; else `points3d.ply` where present).
- Time: with every frame giving `time`, times all inside [0, 1] are used as they are, otherwise
  they are normalised to `(t − t_min) / (t_max − t_min)`; with no frame giving one, frame `k` of the
  `n` in `frames` (file order) gets `k / (n − 1)` (a monocular video). Some frames with `time` and
  others without is an error.
- Images: as D-NeRF's (`load_image`). `mask_path` names a mask whose first channel (integers
  divided by their maximum) multiplies the image's alpha (an RGB image's alpha is 1): masked-out
  pixels show the background. (nerfstudio itself leaves masked pixels out of the loss.)

Splits: the frames fall into the D-NeRF files' three roles, then split exactly as D-NeRF's
(`split_records`; "time" or "future:F"):

- with filename lists (any of the three present; `train_filenames` then required): train =
  the frames in `train_filenames`, val = in `val_filenames`, test = in `test_filenames` (each
  absent list empty; a frame may be in several lists; frames in none are not used).
- without them, held-out cameras: frames with the same `transform_matrix` and intrinsics are one
  camera, numbered in order of first appearance; cameras `heldout_every − 1, 2·heldout_every − 1,
  ...` are held out (fewer cameras than `heldout_every`: none), or the numbers that
  `data.heldout_cameras` names (refused beside filename lists). Under "time", train = the other
  cameras' frames, val = the held-out cameras' frames, test = every frame (its frames after
  `max_time` are the extrapolation). Under "future:F", the pool sorted by time is the train
  cameras' frames only (test is empty), so held-out views never train.
"""

import os
from pathlib import Path

from velogauss.data.dnerf import (INTRINSIC_KEYS, assemble_scene, number, prepare_load, read_intrinsics,
                                  read_json_object, read_pose, resolve_image, split_records)
from velogauss.data.errors import DataError
from velogauss.data.heldout import AUTO, check_heldout, split_cameras
from velogauss.data.ply import read_ply

TRANSFORMS_FILE = "transforms.json"
# Every 8th camera held out when the file lists no split: nerfstudio's `eval_interval` default.
DEFAULT_HELDOUT_EVERY = 8
PINHOLE_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE")
DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
_SPLIT_LISTS = {"train": "train_filenames", "val": "val_filenames", "test": "test_filenames"}


def load_scene(path, max_time=None, half_res=False, background=None, split="time",
               heldout_every=DEFAULT_HELDOUT_EVERY, heldout_cameras=AUTO):
    """Load and validate a nerfstudio-layout scene folder into a `SceneData` (as
    `velogauss.data.dnerf.load_scene`, whose arguments these are, plus `heldout_every`, an int ≥ 2:
    the held-out camera period when `transforms.json` lists no split, and `heldout_cameras`: "auto"
    (that period) or the camera numbers to hold out instead; module docstring).

    Every file is read and checked up front; the first problem raises one `DataError` naming the
    file and field: missing `transforms.json`, image, mask or key; missing intrinsics; a matrix
    that is not 4x4, not finite or not rigid; an unsupported `camera_model` or a non-zero
    distortion coefficient; an image or mask that does not decode; a filename list naming no
    frame; an empty split; held-out cameras named beside filename lists, or cameras the file does
    not have.
    """
    heldout_cameras = check_heldout(heldout_cameras)
    if isinstance(heldout_every, bool) or not isinstance(heldout_every, int) or heldout_every < 2:
        raise DataError(None, "heldout_every", f"expected an integer >= 2, got {heldout_every!r}")
    root, fraction, max_time, background, metadata = prepare_load(path, max_time, half_res, background, split)
    file = root / TRANSFORMS_FILE
    if not file.is_file():
        raise DataError(file, "file", "missing; a nerfstudio scene needs transforms.json")
    meta = read_json_object(file)
    _check_camera_model(file, meta)
    records = _read_frames(file, meta)
    groups, where = _roles(file, meta, records, future=fraction is not None, heldout_every=heldout_every,
                           heldout_cameras=heldout_cameras)
    train, interpolation, extrapolation, max_time = split_records(root, groups, split, fraction, max_time, where)

    if "ply_file_path" in meta:
        if not isinstance(meta["ply_file_path"], str) or not (root / meta["ply_file_path"]).is_file():
            raise DataError(file, "ply_file_path", f"point cloud {meta['ply_file_path']!r} not found in {root}")
        cloud = read_ply(root / meta["ply_file_path"])
    else:
        cloud = read_ply(root / "points3d.ply") if (root / "points3d.ply").is_file() else None
    return assemble_scene(root, train, interpolation, extrapolation, max_time=max_time, split=split,
                          half_res=half_res, background=background, metadata=metadata, cloud=cloud)


def _check_camera_model(file, meta):
    if "camera_model" in meta and meta["camera_model"] not in PINHOLE_MODELS:
        raise DataError(file, "camera_model", f"{meta['camera_model']!r} is not supported; velogauss renders ideal "
                        f"pinhole cameras: one of {', '.join(PINHOLE_MODELS)} (undistort the images first)")


def _read_frames(file, meta):
    """The frame records, in file order, with normalised times (module docstring)."""
    frames = meta.get("frames")
    if not isinstance(frames, list):
        raise DataError(file, "frames", "missing key or not a list of frames")
    if not frames:
        raise DataError(file, "frames", "the file lists no frames")
    records, raw_times = [], []
    for k, frame in enumerate(frames):
        where = f"frames[{k}]"
        if not isinstance(frame, dict):
            raise DataError(file, where, "expected an object")
        if not isinstance(frame.get("file_path"), str):
            raise DataError(file, f"{where}.file_path", "missing key or not a string")
        if "transform_matrix" not in frame:
            raise DataError(file, f"{where}.transform_matrix", "missing key")
        c2w = read_pose(file, f"{where}.transform_matrix", frame["transform_matrix"])
        intrinsics = read_intrinsics(file, meta, frame, where, INTRINSIC_KEYS)
        for key in ("fl_x", "fl_y", "cx", "cy"):
            if key not in intrinsics:
                raise DataError(file, f"{where}.{key}", "missing key: neither the frame nor the top level gives it "
                                "(nerfstudio's pinhole intrinsics fl_x, fl_y, cx, cy are required)")
        for key, (value, field) in read_intrinsics(file, meta, frame, where, DISTORTION_KEYS).items():
            if value != 0.0:
                raise DataError(file, field, f"non-zero distortion coefficient {value!r}: velogauss renders ideal "
                                "pinhole cameras; undistort the images first (then set it to 0 or remove it)")
        if "time" in frame:
            raw_times.append((number(file, f"{where}.time", frame["time"]), f"{where}.time"))
        mask = frame.get("mask_path")
        if mask is not None and not isinstance(mask, str):
            raise DataError(file, f"{where}.mask_path", f"expected a path string, got {mask!r}")
        records.append({"file": file, "where": where, "c2w": c2w, "intrinsics": intrinsics,
                        "file_path": frame["file_path"],
                        "image": resolve_image(file, f"{where}.file_path", frame["file_path"]),
                        "mask": None if mask is None else resolve_image(file, f"{where}.mask_path", mask)})
    n = len(records)
    if raw_times and len(raw_times) != n:
        missing = next(k for k, frame in enumerate(frames) if "time" not in frame)
        raise DataError(file, f"frames[{missing}].time", f"missing key, while {len(raw_times)} of the {n} frames "
                        "give a time: give every frame one, or none (times k / (n - 1) in file order)")
    if not raw_times:
        times = [k / (n - 1) if n > 1 else 0.0 for k in range(n)]
    else:
        values = [t for t, _ in raw_times]
        low, high = min(values), max(values)
        if low >= 0.0 and high <= 1.0:
            times = values
        elif high == low:
            raise DataError(file, raw_times[0][1], f"every frame has time {low!r}, outside [0, 1], so it cannot "
                            "be normalised")
        else:
            times = [(t - low) / (high - low) for t in values]
    for record, time in zip(records, times):
        record["time"] = time
    return records


def _roles(file, meta, records, *, future, heldout_every, heldout_cameras):
    """The records' D-NeRF roles {"train", "val", "test"} and the fields the empty-split errors name."""
    listed = [key for key in _SPLIT_LISTS.values() if key in meta]
    if listed and heldout_cameras != AUTO:
        raise DataError(file, listed[0], "the file lists its own split, so data.heldout_cameras must be \"auto\" "
                        "(remove the filename lists to choose the held-out cameras)")
    if listed:
        if _SPLIT_LISTS["train"] not in meta:
            raise DataError(file, _SPLIT_LISTS["train"], f"missing key, while {', '.join(listed)} "
                            f"{'is' if len(listed) == 1 else 'are'} given")
        groups = {part: _listed(file, key, meta.get(key, []), records) for part, key in _SPLIT_LISTS.items()}
        return groups, {"train": (file, _SPLIT_LISTS["train"]), "test": (file, _SPLIT_LISTS["test"])}
    cameras = {}
    for record in records:
        key = (record["c2w"].tobytes(), tuple(sorted((k, v) for k, (v, _) in record["intrinsics"].items())))
        record["camera_index"] = cameras.setdefault(key, len(cameras))
    if heldout_cameras == AUTO:
        held = [r for r in records if r["camera_index"] % heldout_every == heldout_every - 1]
        kept = [r for r in records if r["camera_index"] % heldout_every != heldout_every - 1]
    else:
        kept, held = split_cameras(records, heldout_cameras, "camera_index", file, "frames")
    groups = {"train": kept, "val": held, "test": [] if future else list(records)}
    return groups, {"train": (file, "frames"), "test": (file, "frames")}


def _listed(file, key, names, records):
    """The records a filename list names, in list order; DataError naming the entry that names none."""
    if not isinstance(names, list):
        raise DataError(file, key, "expected a list of file paths")
    by_path = {}
    for record in records:
        by_path.setdefault(os.path.normpath(record["file_path"]), []).append(record)
        by_path.setdefault(str(record["image"]), []).append(record)
    chosen, seen = [], set()
    for k, name in enumerate(names):
        if not isinstance(name, str):
            raise DataError(file, f"{key}[{k}]", f"expected a file path string, got {name!r}")
        matches = by_path.get(os.path.normpath(name)) or by_path.get(str((Path(file).parent / name).resolve()))
        if not matches:
            raise DataError(file, f"{key}[{k}]", f"{name!r} is no frame's file_path")
        for record in matches:
            if id(record) not in seen:
                seen.add(id(record))
                chosen.append(record)
    return chosen
