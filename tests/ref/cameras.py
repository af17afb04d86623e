"""Cameras for the reference tests: intrinsics, rigid world-to-camera matrices, inverses."""

import numpy as np
from scipy.spatial.transform import Rotation


def intrinsics(fx, fy, cx, cy):
    """K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] in pixels."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def rigid_viewmat(rotvec, t):
    """World-to-camera [[W, t], [0, 1]] with W the rotation of `rotvec` (axis * angle)."""
    viewmat = np.eye(4)
    viewmat[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    viewmat[:3, 3] = t
    return viewmat


def to_world(p, viewmat):
    """World points whose camera-space coordinates are p (..., 3): solves p = W mu + t."""
    return (p - viewmat[:3, 3]) @ viewmat[:3, :3]


def in_view(uv, z, K):
    """Camera-space points (..., 3) at depth z that project to pixel coordinates uv (..., 2)."""
    x = (uv[..., 0] - K[0, 2]) / K[0, 0] * z
    y = (uv[..., 1] - K[1, 2]) / K[1, 1] * z
    return np.stack([x, y, z], axis=-1)
