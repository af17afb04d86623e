"""Held-out cameras chosen by the user (`data.heldout_cameras`): which frames become interpolation views.

A layout's own held-out split (D-NeRF's val file, nerfstudio's filename lists or every 8th camera,
Panoptic's `test_meta.json`) is the default, "auto". A capture without one (a Panoptic folder with
only `train_meta.json`, a nerfstudio file whose cameras the user wants to choose) names the cameras
to hold out; their frames never train and score as interpolation (spec/data.md, "Held-out cameras").
"""

from velogauss.data.errors import DataError

AUTO = "auto"


def check_heldout(value):
    """`value` as a tuple of camera ids, or AUTO; DataError naming `data.heldout_cameras` for anything
    but "auto" or a non-empty list of distinct non-negative integers."""
    if isinstance(value, str) and value == AUTO:
        return AUTO
    ids = tuple(value) if isinstance(value, (list, tuple)) else None
    if (not ids or any(isinstance(i, bool) or not isinstance(i, int) or i < 0 for i in ids)
            or len(set(ids)) != len(ids)):
        raise DataError(None, "data.heldout_cameras", f"expected \"auto\" or a non-empty list of distinct camera "
                        f"ids (integers >= 0), got {value!r}")
    return ids


def split_cameras(records, ids, key, file, field):
    """`(kept, held)`: `records` whose `key` (a camera id) is not / is in `ids`, in their order.

    DataError naming `file` and `field` (the layout's camera-id field) when an id is no camera of
    `records`, with the ids that are, and naming `data.heldout_cameras` when every camera is held out
    (nothing would train)."""
    present = sorted({r[key] for r in records})
    missing = [i for i in ids if i not in present]
    if missing:
        raise DataError(file, field, f"data.heldout_cameras names camera(s) {missing}, which the file does not "
                        f"have; its cameras are {present}")
    if set(present) <= set(ids):
        raise DataError(file, field, f"data.heldout_cameras holds out every camera ({present}), which leaves "
                        "none to train")
    held = [r for r in records if r[key] in ids]
    return [r for r in records if r[key] not in ids], held
