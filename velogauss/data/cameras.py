"""Pinhole cameras in the conventions of spec/conventions.md ("Cameras", "Pixels").

A `Camera` holds a world-to-camera `viewmat` with OpenCV axes (+x right, +y down, +z
forward) and pixel intrinsics `K`. D-NeRF/Blender `transform_matrix` entries
(camera-to-world, OpenGL axes: +y up, +z backward) are converted once, here, by
`viewmat_from_c2w_opengl`. Pixel `(i, j)` is sampled at its centre `(j + 0.5, i + 0.5)`.
"""

from dataclasses import dataclass

import numpy as np

from velogauss_core.checks import check_array, check_scalar
from velogauss_core.constants import POSE_ORTHONORMAL_TOL

# OpenGL -> OpenCV camera axes: flip y (up -> down) and z (backward -> forward).
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def check_rigid(name, matrix):
    """Raise ValueError unless `matrix` (4, 4) is a finite rigid transform; return it as float64.

    Rigid means: bottom row (0, 0, 0, 1) and rotation block R orthonormal
    (`max |RᵀR − I| ≤ POSE_ORTHONORMAL_TOL`, hence `det R ≈ ±1` and R invertible).
    The message starts with `name` and says which condition failed.
    """
    m = np.asarray(check_array(name, np.asarray(matrix, dtype=np.float64), (4, 4)), dtype=np.float64)
    bottom_err = np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]))
    if bottom_err > POSE_ORTHONORMAL_TOL:
        raise ValueError(f"{name}: bottom row must be (0, 0, 0, 1), got {m[3].tolist()}")
    r = m[:3, :3]
    ortho_err = np.max(np.abs(r.T @ r - np.eye(3)))
    if ortho_err > POSE_ORTHONORMAL_TOL:
        raise ValueError(
            f"{name}: rotation block is not a rotation (det = {np.linalg.det(r):.6g}, "
            f"max |RᵀR − I| = {ortho_err:.3g} > {POSE_ORTHONORMAL_TOL}); singular, scaled or sheared pose"
        )
    return m


def viewmat_from_c2w_opengl(c2w_gl):
    """World-to-camera OpenCV `viewmat` (4, 4) from a camera-to-world OpenGL pose (4, 4).

    `c2w_cv = c2w_gl · diag(1, −1, −1, 1)`, `viewmat = inverse(c2w_cv)` (spec/conventions.md).
    Raises ValueError naming `c2w_gl` for a non-finite or non-rigid pose.
    """
    c2w_cv = check_rigid("c2w_gl", c2w_gl) @ _GL_TO_CV
    return np.linalg.inv(c2w_cv)


def c2w_opengl_from_viewmat(viewmat):
    """Camera-to-world OpenGL pose (4, 4) from a world-to-camera OpenCV `viewmat` (4, 4).

    Inverse of `viewmat_from_c2w_opengl`. Raises ValueError naming `viewmat` if not rigid.
    """
    return np.linalg.inv(check_rigid("viewmat", viewmat)) @ _GL_TO_CV


def intrinsics_from_fov(camera_angle_x, width, height):
    """Intrinsics K (3, 3) from the horizontal field of view `camera_angle_x` (radians).

    `fx = fy = 0.5 W / tan(0.5 camera_angle_x)`, `cx = W/2`, `cy = H/2`.
    Raises ValueError naming `camera_angle_x` unless it lies in (0, π).
    """
    check_scalar("camera_angle_x", camera_angle_x)
    if not 0.0 < camera_angle_x < np.pi:
        raise ValueError(f"camera_angle_x: expected a field of view in (0, pi) radians, got {camera_angle_x!r}")
    f = 0.5 * width / np.tan(0.5 * camera_angle_x)
    return intrinsics_from_focal(f, f, 0.5 * width, 0.5 * height)


def intrinsics_from_focal(fl_x, fl_y, cx, cy):
    """Intrinsics K (3, 3) from focal lengths and principal point, all in pixels.

    Raises ValueError naming the argument for a non-finite value or a focal length ≤ 0.
    """
    for name, value in (("fl_x", fl_x), ("fl_y", fl_y), ("cx", cx), ("cy", cy)):
        check_scalar(name, value)
    for name, value in (("fl_x", fl_x), ("fl_y", fl_y)):
        if value <= 0:
            raise ValueError(f"{name}: focal length must be > 0 pixels, got {value!r}")
    return np.array([[fl_x, 0.0, cx], [0.0, fl_y, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """World-to-camera OpenCV `viewmat` (4, 4) of a camera at `eye` looking at `target`.

    `eye`, `target`, `up` (3,) world points/direction; the image's "up" (−y in OpenCV) is the
    projection of `up`. Raises ValueError naming `target` when it equals `eye` and `up`
    when the viewing direction is parallel to it.
    """
    eye = np.asarray(check_array("eye", np.asarray(eye, dtype=np.float64), (3,)))
    target = np.asarray(check_array("target", np.asarray(target, dtype=np.float64), (3,)))
    up = np.asarray(check_array("up", np.asarray(up, dtype=np.float64), (3,)))
    forward = target - eye
    if not np.linalg.norm(forward) > 0:
        raise ValueError("target: must differ from eye")
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, up)
    # |forward × up| / |up| is the sine of the angle between them.
    if not np.linalg.norm(right) > POSE_ORTHONORMAL_TOL * np.linalg.norm(up):
        raise ValueError("up: viewing direction is parallel to up; the camera roll is undefined")
    right = right / np.linalg.norm(right)
    down = np.cross(forward, right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, down, forward], axis=1)
    c2w[:3, 3] = eye
    return np.linalg.inv(c2w)


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera: `viewmat` (4, 4) world-to-camera OpenCV, `K` (3, 3) pixels, image size.

    Both matrices are stored as float64 copies. Construction raises ValueError naming the
    field for a non-rigid `viewmat`, a malformed `K` or a non-positive size.
    """

    viewmat: np.ndarray
    K: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        viewmat = check_rigid("viewmat", self.viewmat).copy()
        K = np.array(check_array("K", np.asarray(self.K, dtype=np.float64), (3, 3)), dtype=np.float64)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[[0, 1, 2, 2, 2], [1, 0, 0, 1, 2]] != [0, 0, 0, 0, 1]):
            raise ValueError(f"K: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {K.tolist()}")
        for name in ("width", "height"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"{name}: expected a positive integer, got {value!r}")
        object.__setattr__(self, "viewmat", viewmat)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    @classmethod
    def from_c2w_opengl(cls, c2w_gl, K, width, height):
        """Camera from a D-NeRF/Blender camera-to-world OpenGL pose (see `viewmat_from_c2w_opengl`)."""
        return cls(viewmat_from_c2w_opengl(c2w_gl), K, width, height)

    @property
    def c2w_opengl(self):
        """The camera-to-world OpenGL pose (4, 4), as written in `transform_matrix`."""
        return c2w_opengl_from_viewmat(self.viewmat)

    @property
    def centre(self):
        """Camera centre in world coordinates (3,): `−Rᵀ t` (spec/rendering.md)."""
        return -self.viewmat[:3, :3].T @ self.viewmat[:3, 3]

    @property
    def forward(self):
        """Unit viewing direction (camera +z) in world coordinates (3,)."""
        return self.viewmat[2, :3] / np.linalg.norm(self.viewmat[2, :3])

    @property
    def fov_x(self):
        """Horizontal field of view in radians, `2 atan(W / (2 fx))`."""
        return 2.0 * np.arctan(0.5 * self.width / self.K[0, 0])

    def project(self, points):
        """Pixel coordinates and depth of world points.

        `points (..., 3)` → `uv (..., 2)` with `u = fx x/z + cx`, `v = fy y/z + cy` (pixel
        centres at `j + 0.5`), and `depth (...,)` = camera-space z (> 0 in front). Points
        with `depth = 0` give non-finite uv.
        """
        p = np.asarray(check_array("points", np.asarray(points, dtype=np.float64), ("...", 3)))
        pc = p @ self.viewmat[:3, :3].T + self.viewmat[:3, 3]
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = self.K[0, 0] * pc[..., 0] / z + self.K[0, 2]
            v = self.K[1, 1] * pc[..., 1] / z + self.K[1, 2]
        return np.stack([u, v], axis=-1), z

    def pixel_rays(self, supersample=1):
        """World rays through pixel (or sub-pixel) centres.

        Returns `origins (H·s, W·s, 3)` (all the camera centre) and unit `directions
        (H·s, W·s, 3)`, `s = supersample`: sample `(a, b)` of the s×s grid in pixel `(i, j)`
        passes through `(j + (b + 0.5)/s, i + (a + 0.5)/s)`; `s = 1` gives the pixel
        centres `(j + 0.5, i + 0.5)`. Row-major, row 0 at the top.
        """
        if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)) or supersample < 1:
            raise ValueError(f"supersample: expected a positive integer, got {supersample!r}")
        s = int(supersample)
        u = (np.arange(self.width * s) + 0.5) / s
        v = (np.arange(self.height * s) + 0.5) / s
        uu, vv = np.meshgrid(u, v)
        d_cam = np.stack(
            [(uu - self.K[0, 2]) / self.K[0, 0], (vv - self.K[1, 2]) / self.K[1, 1], np.ones_like(uu)], axis=-1
        )
        d_world = d_cam @ self.viewmat[:3, :3]  # Rᵀ d for each ray (R rows are camera axes)
        d_world /= np.linalg.norm(d_world, axis=-1, keepdims=True)
        origins = np.broadcast_to(self.centre, d_world.shape).copy()
        return origins, d_world

    def downsampled(self, factor=2):
        """The camera of the image shrunk by an integer `factor` with area averaging.

        Output size `(W // factor, H // factor)`; `fx, fy, cx, cy` are divided by `factor`,
        which is exact for block averaging: pixel `(i, j)` of the small image covers the
        pixels `[f j, f j + f) × [f i, f i + f)` of the large one (trailing rows/columns that
        do not fill a block are cropped, which moves no coordinate).
        """
        if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
            raise ValueError(f"factor: expected a positive integer, got {factor!r}")
        if self.width < factor or self.height < factor:
            raise ValueError(f"factor: {factor} exceeds the image size {self.width}x{self.height}")
        K = self.K.copy()
        K[:2] /= factor
        return Camera(self.viewmat, K, self.width // factor, self.height // factor)
