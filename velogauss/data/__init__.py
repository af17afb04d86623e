"""Datasets: cameras in the spec's conventions, the D-NeRF/NVFi loader, point clouds.

`load_scene(path, max_time=None, half_res=False, background=(1, 1, 1), split="time") -> SceneData`
validates a whole scene folder up front and raises one `DataError` (a ValueError naming
the file and field) for bad data; `check_trainable_size(scene)` refuses images smaller
than the SSIM window before training or evaluation.
"""

from velogauss.data.cameras import Camera
from velogauss.data.dnerf import Frame, SceneData, check_trainable_size, load_scene
from velogauss.data.errors import DataError
from velogauss.data.ply import PointCloud, read_ply, write_ply

__all__ = ["Camera", "DataError", "Frame", "PointCloud", "SceneData", "check_trainable_size", "load_scene", "read_ply", "write_ply"]
