"""Load a dynamic scene in the D-NeRF / NVFi layout, validated in full before training.

Layout (paths relative to the scene folder):

- `transforms_train.json`, `transforms_test.json` (required), `transforms_val.json`
  (optional). Each holds intrinsics -- `camera_angle_x`, or `fl_x, fl_y, cx, cy` -- and
  optionally `w`, `h`, at the top level or per frame (a frame's value wins), plus either
  `frames: [{file_path, time, transform_matrix}, ...]` (D-NeRF; one camera per frame, so
  monocular sequences work as they are) or `data: {camera: {transform_matrix, frames:
  [{file_path, time}, ...]}}` (NVFi; where a frame has no `time`, the NVFi loader's
  `index / (n − 1)` within its camera is used).
- `file_path` with or without extension; without one (or when the file is missing),
  `.png`, `.jpg`, `.jpeg` are tried in that order.
- `transform_matrix`: 4×4 camera-to-world, Blender/OpenGL axes; converted at load
  (spec/conventions.md, "Cameras"). `time` in [0, 1].
- Images: PNG or JPEG, grey, grey+alpha, RGB or RGBA, decoded by Pillow; integer pixels
  are divided by their type's maximum. Alpha is composited over `background`:
  `rgb·a + background·(1 − a)`.
- Optional `points3d.ply` (initial point cloud) and `scene.json` (metadata written by
  `velogauss.scenes.writer`; its `bounds` are the scene's box; its optional `max_time`, the
  scene's own observed window's end, and `background`, its own RGB background, apply where
  the caller gives none or the default, DEFAULT_MAX_TIME and DEFAULT_BACKGROUND).

Splits (`split`), with `max_time` the end of the observed window:

- "time" (the default): `train` = train frames with `t ≤ max_time`; `interpolation` = val
  frames with `t ≤ max_time`, plus test frames with `t ≤ max_time` whose (pose, time) is not a
  train or val frame's; `extrapolation` = test frames with `t > max_time`. Val and train frames
  after `max_time` are not used (the test file is the designated future set).
- "future:F" (ODE-GS's extrapolation protocol on D-NeRF): the train and test frames, train file
  first, each in file order, are sorted by time (stable, so ties keep that order); the first
  `n_train = round(F · n)` of the `n` (Python's `round`, half to even) are `train`, the rest
  `extrapolation`. `max_time` is derived: the last trained frame's time. `interpolation` = val
  frames with `t ≤ max_time` (possibly none). Val frames after it are not used.
- "all" (D-NeRF's standard protocol: the whole clip observed, nothing to extrapolate): `train` =
  every train frame; `interpolation` = every val frame, plus the test frames whose (pose, time)
  is not a train or val frame's; `extrapolation` is empty. `max_time` is derived: the last
  train frame's time.

The other layouts' loaders (velogauss.data.nerfstudio) share this module's public helpers:
`prepare_load` (arguments, scene.json), `read_json_object`, `read_pose`, `read_intrinsics`,
`number`, `number_array`, `resolve_image`, `split_records` (the splits above),
`assemble_scene` (images, cameras, bounds -> SceneData), `load_image`, `camera_from_record`.
"""

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from skimage.transform import downscale_local_mean

from velogauss.config import FUTURE_SPLIT
from velogauss.data.cameras import Camera, check_rigid, intrinsics_from_focal, intrinsics_from_fov
from velogauss.data.errors import DataError
from velogauss.data.ply import read_ply
from velogauss_core.constants import SSIM_WINDOW

INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")  # pinhole intrinsics in pixels, and the image size
_SPLIT_FILES = {"train": "transforms_train.json", "val": "transforms_val.json", "test": "transforms_test.json"}
# The observed window's end when none is given; under "future:F" a max_time equal to it counts as not given.
DEFAULT_MAX_TIME = 0.75
# The colour under transparent pixels when none is given (D-NeRF's white background).
DEFAULT_BACKGROUND = (1.0, 1.0, 1.0)
# `split`'s "future:F", F a decimal strictly inside (0, 1): the pattern velogauss.config's data.split allows.
_FUTURE_SPLIT = re.compile(FUTURE_SPLIT)
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True, eq=False)
class Frame:
    """One image: `pixels (H, W, 3)` uint8 (composited, then kept as 8 bits: `quantized`),
    normalised `time`, its `camera`, and the image file's `path`."""

    pixels: np.ndarray
    time: float
    camera: Camera
    path: str

    @property
    def image(self):
        """(H, W, 3) float32 in [0, 1]: `pixels` / 255, a new array on each call."""
        return self.pixels.astype(np.float32) / np.float32(255)


def quantized(image):
    """(H, W, 3) uint8 of a float image (values clipped to [0, 1]): round(255 c). Images are
    kept as 8 bits so that thousands of frames fit in memory (spec/data.md, "Memory"); the
    rounding error is at most 1/510."""
    return np.rint(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)


@dataclass(frozen=True, eq=False)
class SceneData:
    """A loaded, validated scene.

    `train`, `interpolation`, `extrapolation`: lists of `Frame` (see the module docstring
    for how they are split; `interpolation` may be empty under a "future:F" `split`).
    `max_time`: the observed window's end (derived under "future:F" and "all"); `split`: "time",
    "future:F" or "all"; `extrapolation` is empty under "all". `bounds (2, 3)`: an axis-aligned box `[min, max]` in world
    units -- `scene.json`'s `bounds` if present, else the box of the `points3d.ply` points,
    else the box the cameras look at (`camera_focus_bounds`). `background (3,)` float32.
    `points (N, 3)` / `point_colors (N, 3)`: the PLY cloud, or None. `metadata`: the parsed
    `scene.json`, or None. `root`: the scene folder.
    """

    train: list
    interpolation: list
    extrapolation: list
    bounds: np.ndarray
    background: np.ndarray
    max_time: float
    split: str
    points: np.ndarray | None
    point_colors: np.ndarray | None
    metadata: dict | None
    root: Path

    @property
    def width(self):
        """Image width in pixels (the same for every frame)."""
        return self.train[0].camera.width

    @property
    def height(self):
        """Image height in pixels (the same for every frame)."""
        return self.train[0].camera.height


def load_scene(path, max_time=None, half_res=False, background=None, split="time"):
    """Load and validate a D-NeRF/NVFi scene folder into a `SceneData`.

    `path`: the scene folder. `split`: "time", "future:F" or "all" (module docstring). `max_time`
    in (0, 1]: end of the observed window; None: under "time" scene.json's `max_time` if it
    records one, else DEFAULT_MAX_TIME (which, given, counts as None, as a config cannot tell
    it from its default); derived under "future:F" and "all", where a number other than DEFAULT_MAX_TIME
    must equal the derived end (a run's config.toml records it; anything else would be two
    windows at once). `half_res`: halve the resolution by 2×2 area averaging of the composited
    images (odd trailing rows/columns cropped; `fx, fy, cx, cy` halved). `background (3,)` in
    [0, 1]: colour behind transparent pixels; None (or DEFAULT_BACKGROUND): scene.json's
    `background` if it records one, else DEFAULT_BACKGROUND.

    Every file is read and checked up front; the first problem raises one `DataError`
    naming the file and field: missing file or key, unreadable image, images of different
    sizes or disagreeing with `w`/`h`, non-finite or non-rigid (singular, scaled) pose,
    time outside [0, 1], an empty `train` or `extrapolation` split (with the times found; under
    "future:F" naming `data.split`, F and the counts), a malformed `points3d.ply` or
    `scene.json`. Bad arguments raise `DataError` naming the argument (a ValueError, like every
    bad-input error).
    """
    root, fraction, max_time, background, metadata = prepare_load(path, max_time, half_res, background, split)
    records, where = {}, {}
    for part, name in _SPLIT_FILES.items():
        file = root / name
        where[part] = (file, "frames")
        if not file.is_file():
            if part == "val":
                records[part] = []
                continue
            raise DataError(file, "file", f"missing; a scene needs {_SPLIT_FILES['train']} and {_SPLIT_FILES['test']}")
        records[part] = _read_transforms(file)
    train, interpolation, extrapolation, max_time = split_records(root, records, split, fraction, max_time, where)
    cloud = read_ply(root / "points3d.ply") if (root / "points3d.ply").is_file() else None
    return assemble_scene(root, train, interpolation, extrapolation, max_time=max_time, split=split,
                          half_res=half_res, background=background, metadata=metadata, cloud=cloud)


def prepare_load(path, max_time, half_res, background, split):
    """Check `load_scene`'s arguments (shared by every layout's loader) and read the optional
    `scene.json`; return `(root, fraction, max_time, background, metadata)`.

    `fraction`: F of a "future:F" split, None for "time" and "all". `max_time`: the checked number,
    with scene.json's own where the caller gave none or DEFAULT_MAX_TIME under "time"; None under
    "future:F" and "all" when none was given. `background`: float32 (3,), scene.json's own where the caller
    gave none or DEFAULT_BACKGROUND. `metadata`: the parsed scene.json or None. Raises DataError
    naming the argument, or the missing folder.
    """
    fraction, max_time, background = check_arguments(max_time, half_res, background, split)
    root = Path(path)
    if not root.is_dir():
        raise DataError(root, "path", "scene folder does not exist")
    metadata = _read_metadata(root / "scene.json")
    own = metadata or {}
    if split == "time" and max_time == DEFAULT_MAX_TIME and "max_time" in own:
        max_time = own["max_time"]
    if np.array_equal(background, np.float32(DEFAULT_BACKGROUND)) and "background" in own:
        background = own["background"]
    return root, fraction, max_time, background, metadata


def check_arguments(max_time, half_res, background, split):
    """`(fraction, max_time, background)` of `load_scene`'s arguments, checked before any file is
    read (as `prepare_load` returns them, without scene.json's values); DataError naming the argument."""
    fraction = _check_split(split)
    if max_time is not None or split == "time":
        max_time = _check_max_time(DEFAULT_MAX_TIME if max_time is None else max_time)
    background = _check_background(DEFAULT_BACKGROUND if background is None else background)
    if not isinstance(half_res, (bool, np.bool_)):
        raise DataError(None, "half_res", f"expected True or False, got {half_res!r}")
    return fraction, max_time, background


def split_records(root, records, split, fraction, max_time, where):
    """Split frame records into `(train, interpolation, extrapolation, max_time)` (module docstring,
    "Splits"), shared by every layout's loader.

    `records`: {"train", "val", "test": [record, ...]}, each record a dict with at least `time`
    (normalised) and `c2w`. `fraction`, `max_time`: as `prepare_load` returns them. `where`:
    {"train", "test": (file, field)} named by the empty-split errors.
    """
    if split == "all":
        return _split_all(root, records, split, max_time, where)
    if fraction is not None:
        return _split_future(root, records, split, fraction, max_time)
    return (*_split_time(records, max_time, where), max_time)


def assemble_scene(root, train, interpolation, extrapolation, *, max_time, split, half_res, background, metadata,
                   cloud):
    """Decode the images of the split records and build the `SceneData` (shared by every layout's
    loader). Each record holds `image` (its path), optional `mask` (a mask image's path, multiplied
    into the alpha), `time`, `c2w` (camera-to-world, OpenGL axes), `intrinsics` (as
    `read_intrinsics` returns them) and `file` (the JSON file naming it). DataError for an
    unreadable image or mask, images of different sizes, or intrinsics that disagree with the image.
    """
    size = None
    loaded = {}
    for part, group in (("train", train), ("interpolation", interpolation), ("extrapolation", extrapolation)):
        frames = []
        for record in group:
            image = load_image(record, background)
            if size is None:
                size = (image.shape[0], image.shape[1], record)
            elif image.shape[:2] != size[:2]:
                raise DataError(record["image"], "file_path",
                                f"image is {image.shape[1]}x{image.shape[0]} but {size[2]['image']} is "
                                f"{size[1]}x{size[0]}; all images must have the same size")
            camera = camera_from_record(record, image.shape[1], image.shape[0])
            if half_res:
                image = _halve(image)
                camera = camera.downsampled(2)
            frames.append(Frame(quantized(image), record["time"], camera, str(record["image"])))
        loaded[part] = frames

    if metadata is not None and "bounds" in metadata:
        bounds = metadata["bounds"]
    elif cloud is not None and len(cloud.points):
        bounds = np.stack([cloud.points.min(axis=0), cloud.points.max(axis=0)])
    else:
        bounds = camera_focus_bounds([f.camera for f in loaded["train"]])
    return SceneData(
        train=loaded["train"],
        interpolation=loaded["interpolation"],
        extrapolation=loaded["extrapolation"],
        bounds=np.asarray(bounds, dtype=np.float64),
        background=background,
        max_time=max_time,
        split=split,
        points=None if cloud is None else cloud.points,
        point_colors=None if cloud is None else cloud.colors,
        metadata=metadata,
        root=root,
    )


def _split_time(records, max_time, where):
    """The "time" split's (train, interpolation, extrapolation) records (module docstring)."""
    train = [r for r in records["train"] if r["time"] <= max_time]
    if not train:
        raise DataError(*where["train"],
                        f"empty train split: no frame with time <= max_time={max_time} ({_span(records['train'])})")
    extrapolation = [r for r in records["test"] if r["time"] > max_time]
    if not extrapolation:
        raise DataError(*where["test"],
                        f"empty extrapolation split: no frame with time > max_time={max_time} "
                        f"({_span(records['test'])}); future frames are needed to evaluate extrapolation")
    interpolation = [r for r in records["val"] if r["time"] <= max_time]
    # A test frame inside the window that repeats a train or val (pose, time) is no new view.
    seen = {_pose_time_key(r) for r in train + interpolation}
    interpolation += [r for r in records["test"] if r["time"] <= max_time and _pose_time_key(r) not in seen]
    return train, interpolation, extrapolation


def _split_all(root, records, split, max_time, where):
    """The "all" split's (train, interpolation, [], max_time) records (module docstring); DataError
    for no train frame, or naming `data.max_time` when a given one disagrees with the derived end."""
    train = list(records["train"])
    if not train:
        raise DataError(*where["train"], "empty train split: no frame")
    end = max(r["time"] for r in train)
    _check_window_agrees(root, split, max_time, end, "the last train frame's")
    interpolation = list(records["val"])
    seen = {_pose_time_key(r) for r in train + interpolation}
    interpolation += [r for r in records["test"] if _pose_time_key(r) not in seen]
    return train, interpolation, [], end


def _check_window_agrees(root, split, max_time, end, whose):
    """DataError naming `data.max_time` when a given one (not None, not DEFAULT_MAX_TIME) differs
    from the window's end `end` that `split` derives: two windows at once."""
    if max_time is not None and max_time != DEFAULT_MAX_TIME and not math.isclose(max_time, end, rel_tol=1e-12):
        raise DataError(root, "data.max_time", f"{max_time!r} disagrees with data.split {split!r}, whose observed "
                        f"window ends at {whose} t = {end!r}; leave data.max_time at its default "
                        f"({DEFAULT_MAX_TIME}) under this split")


def _split_future(root, records, split, fraction, max_time):
    """The "future:F" split's (train, interpolation, extrapolation) records and the derived
    `max_time` (module docstring); DataError naming `data.split` when F leaves a side empty
    or the window's end outside (0, 1), and `data.max_time` when a given one disagrees."""
    # sorted() is stable: equal times keep the train file's frames before the test file's.
    pool = sorted(records["train"] + records["test"], key=lambda r: r["time"])
    n = len(pool)
    n_train = round(fraction * n)
    where = f"{split!r} trains on round({fraction:g} x {n}) = {n_train} of the {n} train and test frames"
    if n_train == 0 or n_train == n:
        side = "no train frame" if n_train == 0 else "no future frame to extrapolate to"
        raise DataError(root, "data.split", f"{where}, which leaves {side}; F must give 1 <= round(F x {n}) <= {n - 1}")
    end = pool[n_train - 1]["time"]
    if not 0.0 < end < 1.0:
        raise DataError(root, "data.split", f"{where}; the last of them is at t = {end:g}, but the observed window "
                        "[0, t] must end inside (0, 1)")
    _check_window_agrees(root, split, max_time, end, "the last trained frame's")
    interpolation = [r for r in records["val"] if r["time"] <= end]
    return pool[:n_train], interpolation, pool[n_train:], end


def check_trainable_size(scene):
    """Raise DataError naming an image of `scene` (a `SceneData`) when its images (as loaded,
    after any halving) are smaller than the SSIM window (SSIM_WINDOW pixels a side): the
    training loss and the evaluation's SSIM need one whole window. `load_scene` itself reads
    any size; training and evaluation call this before they start."""
    first = scene.train[0]
    height, width = first.image.shape[:2]
    if min(height, width) < SSIM_WINDOW:
        raise DataError(first.path, "file_path", f"image is {width}x{height} pixels as loaded, smaller than the "
                        f"{SSIM_WINDOW}x{SSIM_WINDOW} SSIM window (SSIM_WINDOW) of the loss and metrics")


def camera_focus_bounds(cameras):
    """The box the cameras look at: centred on the least-squares closest point to all optical
    axes, half-size the mean camera distance to it times `tan(fov_x / 2)` (half the width
    the image spans at that depth). `cameras`: a non-empty list of `Camera`. Returns `(2, 3)`.

    Parallel optical axes have no closest point; lstsq's minimum-norm solution is used then.
    """
    centres = np.stack([c.centre for c in cameras])
    dirs = np.stack([c.forward for c in cameras])
    projectors = np.eye(3) - dirs[:, :, None] * dirs[:, None, :]
    focus = np.linalg.lstsq(projectors.sum(axis=0), np.einsum("nij,nj->i", projectors, centres), rcond=None)[0]
    half = np.mean([np.linalg.norm(c.centre - focus) * np.tan(0.5 * c.fov_x) for c in cameras])
    return np.stack([focus - half, focus + half])


def _check_max_time(max_time):
    if isinstance(max_time, bool) or not isinstance(max_time, (int, float, np.integer, np.floating)):
        raise DataError(None, "max_time", f"expected a number in (0, 1], got {max_time!r}")
    if not 0.0 < float(max_time) <= 1.0:
        raise DataError(None, "max_time", f"expected a number in (0, 1] (the observed window's end), got {max_time!r}")
    return float(max_time)


def _check_split(split):
    """None for "time" and "all", F for "future:F"; DataError naming `split` otherwise."""
    match = _FUTURE_SPLIT.fullmatch(split) if isinstance(split, str) else None
    if split not in ("time", "all") and match is None:
        raise DataError(None, "split", f'expected "time", "all" or "future:F" with F a decimal in (0, 1), got {split!r}')
    return None if match is None else float(match.group(1))


def _check_background(background):
    value = np.asarray(background, dtype=np.float64) if np.ndim(background) else None
    if value is None or value.shape != (3,) or not np.all(np.isfinite(value)) or value.min() < 0 or value.max() > 1:
        raise DataError(None, "background", f"expected an RGB triple in [0, 1], got {background!r}")
    return value.astype(np.float32)


def _span(records):
    if not records:
        return "the file lists no frames"
    times = [r["time"] for r in records]
    return f"{len(times)} frames with times in [{min(times):.4g}, {max(times):.4g}]"


def _pose_time_key(record):
    return (record["time"], record["c2w"].tobytes())


def _read_transforms(file):
    meta = read_json_object(file)
    if "frames" in meta:
        frames = meta["frames"]
        if not isinstance(frames, list):
            raise DataError(file, "frames", "expected a list of frames")
        entries = [(f"frames[{k}]", frame, None, None) for k, frame in enumerate(frames)]
    elif "data" in meta and isinstance(meta["data"], dict):
        entries = []
        for cam, block in meta["data"].items():
            where = f"data.{cam}"
            if not isinstance(block, dict) or not isinstance(block.get("frames"), list):
                raise DataError(file, f"{where}.frames", "missing or not a list")
            if "transform_matrix" not in block:
                raise DataError(file, f"{where}.transform_matrix", "missing key")
            n = len(block["frames"])
            for k, frame in enumerate(block["frames"]):
                default_time = k / (n - 1) if n > 1 else 0.0
                entries.append((f"{where}.frames[{k}]", frame, block["transform_matrix"], default_time))
    else:
        raise DataError(file, "frames", "missing key (neither D-NeRF 'frames' nor NVFi 'data')")
    return [_read_frame(file, meta, *entry) for entry in entries]


def _read_frame(file, meta, where, frame, shared_pose, default_time):
    if not isinstance(frame, dict):
        raise DataError(file, where, "expected an object")
    if "file_path" not in frame or not isinstance(frame["file_path"], str):
        raise DataError(file, f"{where}.file_path", "missing key or not a string")
    pose = frame.get("transform_matrix", shared_pose)
    if pose is None:
        raise DataError(file, f"{where}.transform_matrix", "missing key")
    c2w = read_pose(file, f"{where}.transform_matrix", pose)
    if "time" in frame:
        time = number(file, f"{where}.time", frame["time"])
    elif default_time is not None:
        time = default_time
    else:
        raise DataError(file, f"{where}.time", "missing key")
    if not 0.0 <= time <= 1.0:
        raise DataError(file, f"{where}.time", f"time {time!r} is outside [0, 1]")
    intrinsics = read_intrinsics(file, meta, frame, where, ("camera_angle_x",) + INTRINSIC_KEYS)
    if "camera_angle_x" not in intrinsics and "fl_x" not in intrinsics:
        raise DataError(file, "camera_angle_x", "missing key (need camera_angle_x or fl_x, fl_y, cx, cy)")
    return {"file": file, "where": where, "time": time, "c2w": c2w, "intrinsics": intrinsics,
            "image": resolve_image(file, f"{where}.file_path", frame["file_path"])}


def read_intrinsics(file, meta, frame, where, keys):
    """`{key: (value, field)}` for each of `keys` that the `frame` object (field `<where>.<key>`) or
    else the top-level `meta` object (field `<key>`) of JSON `file` gives: a frame's value wins.
    DataError naming the field for a value that is not a finite number."""
    intrinsics = {}
    for key in keys:
        if key in frame:
            field, value = f"{where}.{key}", frame[key]
        elif key in meta:
            field, value = key, meta[key]
        else:
            continue
        intrinsics[key] = (number(file, field, value), field)
    return intrinsics


def read_pose(file, field, value):
    """A camera-to-world `transform_matrix` (4, 4) float64 from JSON `value`; DataError naming `file`
    and `field` unless it is a finite, rigid 4x4 matrix (`check_rigid`)."""
    c2w = number_array(file, field, value, (4, 4))
    try:
        check_rigid("transform_matrix", c2w)
    except ValueError as err:
        raise DataError(file, field, str(err).split(": ", 1)[-1]) from None
    return c2w


def read_json_object(file):
    """The JSON object in `file`; DataError naming it (field "file") when unreadable, not JSON, or
    not an object at the top level."""
    try:
        meta = json.loads(file.read_text())
    except OSError as err:
        raise DataError(file, "file", f"cannot read ({err.strerror or err})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DataError(file, "file", f"not valid JSON ({err})") from None
    if not isinstance(meta, dict):
        raise DataError(file, "file", "expected a JSON object at the top level")
    return meta


def number(file, field, value):
    """`value` as a float; DataError naming `file` and `field` unless it is a finite JSON number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DataError(file, field, f"expected a number, got {value!r}")
    if not math.isfinite(value):
        raise DataError(file, field, f"non-finite value {value!r}")
    return float(value)


def number_array(file, field, value, shape):
    """`value` as a float64 array of `shape`; DataError naming `file` and `field` for another shape,
    non-numbers or non-finite entries."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(file, field, f"expected a {shape[0]}x{shape[1]} array of numbers") from None
    if array.shape != shape:
        raise DataError(file, field, f"expected shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise DataError(file, field, "contains non-finite values (NaN or inf)")
    return array


def resolve_image(file, field, file_path):
    """The image file that `file_path` (relative to JSON `file`'s folder, extension optional: `.png`,
    `.jpg`, `.jpeg` are tried) names; DataError naming `file` and `field` when none exists."""
    base = (file.parent / file_path).resolve()
    candidates = [base] if base.suffix.lower() in _IMAGE_SUFFIXES else []
    candidates += [base.with_name(base.name + suffix) for suffix in _IMAGE_SUFFIXES]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise DataError(file, field,
                    f"image {file_path!r} not found (tried {', '.join(c.name for c in candidates)} in {base.parent})")


def load_image(record, background):
    """The record's image (H, W, 3) float32, its alpha (the image's own, times the record's optional
    `mask`'s first channel) composited over `background`: `rgb·a + background·(1 − a)`. DataError
    naming the image (field "file_path") or the mask (field "mask_path") when unreadable, of an
    unsupported kind, non-finite, or (a mask) of another size than the image."""
    image = _decode(record["image"], "file_path")
    channels = image.shape[2]
    rgb = np.repeat(image[..., :1], 3, axis=2) if channels in (1, 2) else image[..., :3]
    alpha = image[..., -1:] if channels in (2, 4) else None
    if record.get("mask") is not None:
        mask = _decode(record["mask"], "mask_path")[..., :1]
        if mask.shape[:2] != image.shape[:2]:
            raise DataError(record["mask"], "mask_path", f"mask is {mask.shape[1]}x{mask.shape[0]} but its image "
                            f"{record['image']} is {image.shape[1]}x{image.shape[0]}")
        alpha = mask if alpha is None else alpha * mask
    if alpha is not None:
        rgb = rgb * alpha + background * (1.0 - alpha)
    return np.ascontiguousarray(rgb, dtype=np.float32)


def _decode(path, field):
    """Image file `path` as float32 (H, W, C), C in 1..4, integer pixels divided by their type's maximum."""
    try:
        raw = iio.imread(path, plugin="pillow")
    except Exception as err:  # imageio raises many plugin-specific types for corrupt files
        raise DataError(path, field, f"unreadable image ({type(err).__name__}: {err})") from None
    if raw.dtype.kind == "b":  # 1-bit PNG: pillow reads it as bool
        image = raw.astype(np.float32)
    elif raw.dtype.kind == "u":
        image = raw.astype(np.float32) / np.float32(np.iinfo(raw.dtype).max)
    elif raw.dtype.kind == "f":
        image = raw.astype(np.float32)
    else:
        raise DataError(path, field, f"unsupported pixel type {raw.dtype}")
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[2] not in (1, 2, 3, 4):
        raise DataError(path, field, f"expected a grey, grey+alpha, RGB or RGBA image, got shape {raw.shape}")
    if not np.all(np.isfinite(image)):
        raise DataError(path, field, "image contains non-finite values")
    return image


def camera_from_record(record, width, height):
    """The `Camera` of a frame record (`record["intrinsics"]` as `read_intrinsics` returns them:
    `camera_angle_x`, or `fl_x, fl_y, cx, cy`; optional `w, h` checked against the image's
    `width`, `height`; `record["c2w"]` camera-to-world OpenGL, converted by
    `Camera.from_c2w_opengl`). DataError naming the JSON file and field otherwise."""
    file, intr = record["file"], record["intrinsics"]
    for key, actual in (("w", width), ("h", height)):
        if key in intr and intr[key][0] != actual:
            raise DataError(file, intr[key][1], f"says {intr[key][0]:g} pixels but {record['image']} has {actual}")
    if "fl_x" in intr:
        missing = [k for k in ("fl_y", "cx", "cy") if k not in intr]
        if missing:
            where = record.get("where")
            raise DataError(file, missing[0] if where is None else f"{where}.{missing[0]}",
                            "missing key (fl_x is given, so fl_y, cx, cy are needed); neither the frame nor the "
                            "top level gives it")
        for key in ("fl_x", "fl_y"):
            if intr[key][0] <= 0:
                raise DataError(file, intr[key][1], f"focal length must be > 0 pixels, got {intr[key][0]!r}")
        K = intrinsics_from_focal(intr["fl_x"][0], intr["fl_y"][0], intr["cx"][0], intr["cy"][0])
    else:
        fov, field = intr["camera_angle_x"]
        if not 0.0 < fov < math.pi:
            raise DataError(file, field, f"expected a field of view in (0, pi) radians, got {fov!r}")
        K = intrinsics_from_fov(fov, width, height)
    return Camera.from_c2w_opengl(record["c2w"], K, width, height)


def _halve(image):
    h, w = image.shape[0] // 2, image.shape[1] // 2
    if h == 0 or w == 0:
        raise DataError(None, "half_res", f"image of {image.shape[1]}x{image.shape[0]} pixels is too small to halve")
    # Area (box) averaging over 2×2 blocks; an odd last row/column is dropped, as in D-NeRF.
    return downscale_local_mean(image[:2 * h, :2 * w], (2, 2, 1)).astype(np.float32)


def _read_metadata(file):
    if not file.is_file():
        return None
    try:
        meta = json.loads(file.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as err:
        raise DataError(file, "file", f"not readable JSON ({err})") from None
    if not isinstance(meta, dict):
        raise DataError(file, "file", "expected a JSON object at the top level")
    if "bounds" in meta:
        bounds = number_array(file, "bounds", meta["bounds"], (2, 3))
        if np.any(bounds[0] > bounds[1]):
            raise DataError(file, "bounds", f"min {bounds[0].tolist()} exceeds max {bounds[1].tolist()}")
        meta["bounds"] = bounds
    if "max_time" in meta:
        value = meta["max_time"]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 < value < 1.0:
            raise DataError(file, "max_time", f"expected a number in (0, 1), got {value!r}")
        meta["max_time"] = float(value)
    if "background" in meta:
        try:
            meta["background"] = _check_background(meta["background"])
        except (TypeError, ValueError):  # NumPy's, for values that are not numbers
            raise DataError(file, "background",
                            f"expected an RGB triple in [0, 1], got {meta['background']!r}") from None
    return meta
