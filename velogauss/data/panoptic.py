"""Load a dynamic scene in the Dynamic3DGaussians / CMU Panoptic layout, validated in full before training.

The layout is that of Dynamic3DGaussians' prepared Panoptic sequences (JonathonLuiten/Dynamic3DGaussians,
train.py: `construct_timestep_dataset`, `initialize_params`). Paths are relative to the scene folder:

- `train_meta.json` (required) and `test_meta.json` (optional): `w`, `h` (the image size, pixels) and,
  per time step `t` and camera `c`, `k[t][c]` (3x3 pinhole intrinsics, pixels, no skew),
  `w2c[t][c]` (4x4 world-to-camera, already OpenCV axes: +x right, +y down, +z forward),
  `fn[t][c]` (the image, `"<cam>/<frame>.jpg"`, relative to `ims/`) and `cam_id[t][c]` (an integer).
  The four lists have one entry per time step, each with the same number of cameras at every step.
  The camera is converted to the shared OpenGL camera-to-world record once at load
  (`c2w_gl = w2c⁻¹ · diag(1, −1, −1, 1)`), so `Camera.viewmat` is `w2c` again up to rounding.
- Images `ims/<cam>/<frame>.jpg` (JPEG, no alpha, decoded as D-NeRF's: `load_image`); optional masks
  `seg/<cam>/<frame>.png` (the image's name with `.jpg` replaced by `.png`, as the authors' loader
  reads it): where present, the mask's first channel (integers divided by their type's maximum) is
  the alpha, so masked-out pixels show the background (`rgb·m + background·(1 − m)`).
- Time: step `t` of the `T` time steps gets `t / (T − 1)` (0 when T = 1). `test_meta.json` must have
  the same `T`.
- Optional `init_pt_cld.npz` with array `data` (N, 7): x, y, z, r, g, b (in [0, 1]), seg (as the
  authors' `initialize_params` reads it): its xyz and rgb are the initial point cloud.

Splits: `train_meta.json`'s frames are the train role, `test_meta.json`'s (the held-out interpolation
cameras) the val role, joined by the frames of the `cam_id`s named in `data.heldout_cameras` (a
capture without `test_meta.json` then has held-out views too); then, exactly as the nerfstudio
loader without filename lists, under "time" the test role is every frame (its frames after
`max_time` are the extrapolation), under "future:F" the test role is empty, so the time-sorted
pool is the train cameras' frames and held-out views never train. `split_records` does the
rest, as for every layout.
"""

from pathlib import Path

import numpy as np

from velogauss.data.cameras import check_rigid
from velogauss.data.dnerf import (assemble_scene, number, number_array, prepare_load, read_json_object,
                                  resolve_image, split_records)
from velogauss.data.errors import DataError
from velogauss.data.heldout import AUTO, check_heldout, split_cameras
from velogauss.data.ply import PointCloud

TRAIN_META = "train_meta.json"
TEST_META = "test_meta.json"
POINT_CLOUD_FILE = "init_pt_cld.npz"
IMAGE_DIR = "ims"
MASK_DIR = "seg"
_PER_STEP_KEYS = ("k", "w2c", "fn", "cam_id")
_OPENGL_FROM_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])


def load_scene(path, max_time=None, half_res=False, background=None, split="time", heldout_cameras=AUTO):
    """Load and validate a Panoptic-layout scene folder into a `SceneData` (as
    `velogauss.data.dnerf.load_scene`, whose arguments these are, plus `heldout_cameras`: "auto", or
    `cam_id`s of `train_meta.json` whose frames are held out beside `test_meta.json`'s; module
    docstring for the layout).

    Every file is read and checked up front; the first problem raises one `DataError` naming the
    file and field: missing `train_meta.json`, key or image; `w`/`h` not positive integers or
    disagreeing with the images; a `k` not 3x3 (or with skew, a non-unit last row), a `w2c` not 4x4 or
    not rigid, NaN or inf in either; lists of different lengths or camera counts that change across
    time steps; a JPEG or mask that does not decode; a malformed `init_pt_cld.npz`; an empty split; a
    held-out `cam_id` that `train_meta.json` does not have, or every one of them.
    """
    heldout_cameras = check_heldout(heldout_cameras)
    root, fraction, max_time, background, metadata = prepare_load(path, max_time, half_res, background, split)
    train_file, test_file = root / TRAIN_META, root / TEST_META
    if not train_file.is_file():
        raise DataError(train_file, "file", f"missing; a Panoptic scene needs {TRAIN_META} (and {TEST_META} for "
                        "held-out cameras)")
    train = _read_meta(train_file)
    held = _read_meta(test_file) if test_file.is_file() else []
    if held and held[-1]["steps"] != train[-1]["steps"]:
        raise DataError(test_file, "fn", f"has {held[-1]['steps']} time steps but {TRAIN_META} has "
                        f"{train[-1]['steps']}; both must cover the same time steps")
    every = train + held
    if heldout_cameras != AUTO:
        train, chosen = split_cameras(train, heldout_cameras, "cam_id", train_file, "cam_id")
        held = held + chosen
    groups = {"train": train, "val": held, "test": [] if fraction is not None else every}
    where = {"train": (train_file, "fn"), "test": (train_file, "fn")}
    train, interpolation, extrapolation, max_time = split_records(root, groups, split, fraction, max_time, where)
    cloud = _read_point_cloud(root / POINT_CLOUD_FILE) if (root / POINT_CLOUD_FILE).is_file() else None
    return assemble_scene(root, train, interpolation, extrapolation, max_time=max_time, split=split,
                          half_res=half_res, background=background, metadata=metadata, cloud=cloud)


def _read_meta(file):
    """The frame records of one meta file, time step by time step, cameras in file order."""
    meta = read_json_object(file)
    size = {}
    for key in ("w", "h"):
        if key not in meta:
            raise DataError(file, key, "missing key (the image size in pixels)")
        value = number(file, key, meta[key])
        if value != int(value) or value <= 0:
            raise DataError(file, key, f"expected a positive integer, got {meta[key]!r}")
        size[key] = (value, key)
    lists = {}
    for key in _PER_STEP_KEYS:
        if not isinstance(meta.get(key), list):
            raise DataError(file, key, "missing key or not a list (one entry per time step)")
        lists[key] = meta[key]
    steps = len(lists["fn"])
    if steps == 0:
        raise DataError(file, "fn", "the file lists no time step")
    for key in _PER_STEP_KEYS:
        if len(lists[key]) != steps:
            raise DataError(file, key, f"has {len(lists[key])} time steps but fn has {steps}")
    n_cams = None
    records = []
    for t in range(steps):
        for key in _PER_STEP_KEYS:
            entry = lists[key][t]
            if not isinstance(entry, list):
                raise DataError(file, f"{key}[{t}]", "expected a list (one entry per camera)")
            if n_cams is None:
                n_cams = len(entry)
                if n_cams == 0:
                    raise DataError(file, f"{key}[0]", "time step 0 lists no camera")
            elif len(entry) != n_cams:
                raise DataError(file, f"{key}[{t}]", f"has {len(entry)} cameras but {_PER_STEP_KEYS[0]}[0] has "
                                f"{n_cams}; every time step must list the same cameras")
        for c in range(n_cams):
            records.append(_read_camera(file, size, lists, t, c, steps))
    return records


def _read_camera(file, size, lists, t, c, steps):
    """The record of camera `c` at time step `t` (fields `k[t][c]`, `w2c[t][c]`, `fn[t][c]`, `cam_id[t][c]`)."""
    index = f"[{t}][{c}]"
    K = number_array(file, f"k{index}", lists["k"][t][c], (3, 3))
    if K[0, 1] != 0 or K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise DataError(file, f"k{index}", f"expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (pinhole, no skew), "
                        f"got {K.tolist()}")
    w2c = number_array(file, f"w2c{index}", lists["w2c"][t][c], (4, 4))
    try:
        check_rigid("w2c", w2c)
    except ValueError as err:
        raise DataError(file, f"w2c{index}", str(err).split(": ", 1)[-1]) from None
    name = lists["fn"][t][c]
    if not isinstance(name, str) or not name:
        raise DataError(file, f"fn{index}", f"expected an image path string relative to {IMAGE_DIR}/, got {name!r}")
    cam_id = lists["cam_id"][t][c]
    if isinstance(cam_id, bool) or not isinstance(cam_id, int):
        raise DataError(file, f"cam_id{index}", f"expected an integer camera id, got {cam_id!r}")
    field = f"k{index}"
    intrinsics = {"fl_x": (K[0, 0], field), "fl_y": (K[1, 1], field), "cx": (K[0, 2], field),
                  "cy": (K[1, 2], field), **size}
    mask = (file.parent / MASK_DIR / name).with_suffix(".png")
    return {"file": file, "where": f"fn{index}", "time": t / (steps - 1) if steps > 1 else 0.0,
            "c2w": np.linalg.inv(w2c) @ _OPENGL_FROM_OPENCV, "intrinsics": intrinsics, "cam_id": cam_id,
            "image": resolve_image(file, f"fn{index}", str(Path(IMAGE_DIR) / name)),
            "mask": mask if mask.is_file() else None, "steps": steps}


def _read_point_cloud(file):
    """`init_pt_cld.npz`'s `data` (N, 7) as a `PointCloud` (xyz, rgb); DataError naming the file and field."""
    try:
        with np.load(file, allow_pickle=False) as archive:
            if "data" not in archive.files:
                raise DataError(file, "data", f"missing array (the archive holds {sorted(archive.files)})")
            data = np.asarray(archive["data"])
    except DataError:
        raise
    except Exception as err:  # zipfile, pickle and format errors of a corrupt archive
        raise DataError(file, "file", f"unreadable .npz archive ({type(err).__name__}: {err})") from None
    if data.ndim != 2 or data.shape[1] != 7 or data.dtype.kind not in "fiu":
        raise DataError(file, "data", f"expected a numeric (N, 7) array of x, y, z, r, g, b, seg, got "
                        f"{data.dtype} {data.shape}")
    if not np.all(np.isfinite(data)):
        raise DataError(file, "data", "contains non-finite values (NaN or inf)")
    colors = data[:, 3:6].astype(np.float32)
    if colors.size and (colors.min() < 0 or colors.max() > 1):
        raise DataError(file, "data", "colours (columns 3-5) must be in [0, 1]")
    return PointCloud(data[:, :3].astype(np.float64), colors)
