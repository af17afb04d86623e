"""What the viewer draws: a browser camera turned into a velogauss `Camera`, and one frame.

`camera_from_pose` reads viser's camera (camera-to-world `wxyz`, `position`, vertical field
of view, aspect; OpenCV axes: +z forward, +y down, the convention of spec/conventions.md)
into a world-to-camera `Camera` of a given pixel size; `pose_from_camera` is its inverse,
used to start the orbit at a training camera and to draw the ground-truth frusta.

`FrameRenderer.render(camera, t, physics_only)` is the render callback: under
`torch.no_grad`, the model's Gaussians at time t (the full model, or the physics-only base
state x*, q*, s* of VG-TRAJ, i.e. the ADF switched off, VG-ADF-COMPOSE) rasterized by
`velogauss_fast.rasterize` with its default backend (numba on the CPU, gsplat or torch on
CUDA). The Gaussians at one (t, mode) are kept, so orbiting at a fixed time only rasterizes.
`annotate` writes onto the frame whether t is in the observed window or the future.
"""

import threading

import numpy as np
import torch
import viser.transforms as vtf
from PIL import Image, ImageDraw, ImageFont

from velogauss.data.cameras import Camera
from velogauss.io_utils import to_uint8
from velogauss.model.velogauss_model import render_gaussians

OBSERVED_COLOR = (38, 140, 64)
FUTURE_COLOR = (217, 51, 38)
# Height of the banner that says observed / future, in pixels; enough for PIL's default font.
BANNER_HEIGHT = 14


def camera_from_pose(wxyz, position, fov_y, aspect, height):
    """A pinhole `Camera` of `height` rows and `round(height * aspect)` columns (at least 1)
    for a camera-to-world rotation `wxyz (4,)` and centre `position (3,)`, with vertical field
    of view `fov_y` radians; principal point at the image centre, square pixels."""
    height = max(1, int(round(height)))
    width = max(1, int(round(height * aspect)))
    c2w = np.eye(4)
    c2w[:3, :3] = vtf.SO3(np.asarray(wxyz, dtype=np.float64)).as_matrix()
    c2w[:3, 3] = np.asarray(position, dtype=np.float64)
    f = 0.5 * height / np.tan(0.5 * fov_y)
    K = np.array([[f, 0.0, 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])
    return Camera(np.linalg.inv(c2w), K, width, height)


def pose_from_camera(camera):
    """`(wxyz (4,), position (3,), fov_y, aspect)` of a `Camera` for viser (its inverse above)."""
    c2w = np.linalg.inv(camera.viewmat)
    wxyz = vtf.SO3.from_matrix(c2w[:3, :3]).wxyz
    fov_y = 2.0 * np.arctan(0.5 * camera.height / camera.K[1, 1])
    return wxyz, c2w[:3, 3].copy(), float(fov_y), camera.width / camera.height


class FrameRenderer:
    """Renders a trained `VeloGaussModel` for the viewer (see the module docstring).

    `background`: RGB (3,) in [0, 1]. Thread-safe: one frame at a time (torch and numba
    already use every thread they were given); whoever else evaluates the model (the viewer's
    overlays) holds `lock` too.
    """

    def __init__(self, model, background):
        self.model = model.eval()
        self.background = tuple(float(c) for c in background)
        self.lock = threading.RLock()
        self._key = None
        self._gaussians = None

    def gaussians(self, t, physics_only=False):
        """The `render_inputs_at` dict at time t, of the full model or the physics-only base state."""
        key = (float(t), bool(physics_only))
        if key != self._key:
            # Physics-only is the model's own spec with the ADF skipped (VG-ADF-COMPOSE).
            spec = self.model.spec.without_adf() if physics_only else None
            with self.lock, torch.no_grad():
                means, quats, scales, _ = self.model.state_at(float(t), spec=spec)
                self._gaussians = self.model.with_appearance(means, quats, scales)
            self._key = key
        return self._gaussians

    def render(self, camera, t, physics_only=False):
        """The image (H, W, 3) float in [0, 1] (a NumPy array) of `camera` at time t."""
        with self.lock, torch.no_grad():
            image, _, _ = render_gaussians(self.gaussians(t, physics_only), camera, self.background)
            return image.detach().cpu().numpy()




def annotate(image, t, max_time):
    """`image` (H, W, 3) in [0, 1] → uint8 with a banner on top: the time and "observed" (green)
    for t ≤ max_time, "FUTURE (extrapolated)" (red) beyond it."""
    frame = Image.fromarray(to_uint8(image))
    draw = ImageDraw.Draw(frame)
    future = t > max_time
    text = f"t={t:.3f}  " + (f"FUTURE (extrapolated, t > {max_time:g})" if future else f"observed (t <= {max_time:g})")
    draw.rectangle([0, 0, frame.width, BANNER_HEIGHT - 1], fill=FUTURE_COLOR if future else OBSERVED_COLOR)
    draw.text((3, 1), text, fill=(255, 255, 255), font=ImageFont.load_default())
    return np.asarray(frame)
