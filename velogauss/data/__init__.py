"""Datasets: cameras in the spec's conventions, the D-NeRF/NVFi, nerfstudio and Panoptic loaders, point clouds.

`load_scene(path, max_time=None, half_res=False, background=(1, 1, 1), split="time", format="auto",
heldout_cameras="auto") -> SceneData` detects the folder's layout (or takes `format`: "dnerf",
"nerfstudio", "panoptic"), takes the layout's held-out cameras or the ones named, validates
the whole scene folder up front and raises one `DataError` (a ValueError naming the file and
field) for bad data; `check_trainable_size(scene)` refuses images smaller than the SSIM window
before training or evaluation.
"""

from pathlib import Path

from velogauss.data import dnerf, nerfstudio, panoptic
from velogauss.data.cameras import Camera
from velogauss.data.dnerf import Frame, SceneData, check_trainable_size
from velogauss.data.errors import DataError
from velogauss.data.heldout import AUTO, check_heldout
from velogauss.data.ply import PointCloud, read_ply, write_ply

# Each layout's loader and the files that mark a folder as that layout (all of them present).
LAYOUTS = {
    "dnerf": (dnerf.load_scene, ("transforms_train.json", "transforms_test.json")),
    "nerfstudio": (nerfstudio.load_scene, (nerfstudio.TRANSFORMS_FILE,)),
    "panoptic": (panoptic.load_scene, (panoptic.TRAIN_META,)),
}
FORMATS = ("auto",) + tuple(LAYOUTS)


def detect_format(path):
    """The layout of scene folder `path`: "dnerf" when it holds `transforms_train.json`,
    "nerfstudio" when it holds `transforms.json`, "panoptic" when it holds `train_meta.json`.
    DataError naming the folder when it is missing, holds several (name one with `format`) or
    none (the message lists each layout's files)."""
    root = Path(path)
    if not root.is_dir():
        raise DataError(root, "path", "scene folder does not exist")
    found = [name for name, (_, files) in LAYOUTS.items() if (root / files[0]).is_file()]
    expected = "; ".join(f"{name}: {' and '.join(files)}" for name, (_, files) in LAYOUTS.items())
    if len(found) > 1:
        raise DataError(root, "format", f"the folder holds the files of several layouts ({expected}); choose one "
                        "with format= (velogauss train --format, config data.format)")
    if not found:
        raise DataError(root, "format", f"no known scene layout; expected the files of one of: {expected}")
    return found[0]


def load_scene(path, max_time=None, half_res=False, background=None, split="time", format="auto",
               heldout_cameras=AUTO):
    """Load and validate the scene folder `path` into a `SceneData`: `format` "auto" (the default)
    detects the layout (`detect_format`), "dnerf", "nerfstudio" or "panoptic" forces one;
    `heldout_cameras` "auto" keeps the layout's own held-out split, a list of camera ids holds those
    cameras out (nerfstudio and Panoptic; `velogauss.data.heldout`); the other arguments are those of
    `velogauss.data.dnerf.load_scene`. DataError naming `format` for another value, and
    `data.heldout_cameras` for ids given to a D-NeRF folder (its val file is the held-out split)."""
    if format not in FORMATS:
        raise DataError(None, "format", f"expected one of {', '.join(FORMATS)}, got {format!r}")
    dnerf.check_arguments(max_time, half_res, background, split)  # bad arguments first, whatever the folder
    heldout_cameras = check_heldout(heldout_cameras)
    layout = detect_format(path) if format == "auto" else format
    loader = LAYOUTS[layout][0]
    options = dict(max_time=max_time, half_res=half_res, background=background, split=split)
    if heldout_cameras == AUTO:
        return loader(path, **options)
    if layout == "dnerf":
        raise DataError(path, "data.heldout_cameras", "a D-NeRF folder has no camera ids (its held-out views "
                        "are transforms_val.json's); leave it \"auto\"")
    return loader(path, heldout_cameras=heldout_cameras, **options)


__all__ = ["Camera", "DataError", "FORMATS", "LAYOUTS", "Frame", "PointCloud", "SceneData", "check_trainable_size",
           "detect_format", "load_scene", "read_ply", "write_ply"]
