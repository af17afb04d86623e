"""The canonical 3D Gaussians (paper Sec. "Canonical 3D Representation"): their state at t = 0.

Parameters are stored unconstrained, as in 3DGS: log scales, opacity logits, raw
quaternions (normalised where used, VG-QUAT), and SH coefficients split into the degree-0
term and the rest (they get different learning rates). Densification replaces the
parameter tensors (`set_tensors`); the optimiser is told separately (velogauss.train.optim).
"""

import numpy as np
import torch
from scipy.spatial import cKDTree
from torch import nn

from velogauss_fast.sh import C0

FIELDS = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")
# Initial scale of a Gaussian relative to the mean distance to its 3 nearest neighbours
# (3DGS uses the distance itself; the synthetic point clouds are sparse surface samples).
_NEIGHBOURS = 3


class Gaussians(nn.Module):
    """N canonical Gaussians: means (N, 3), log_scales (N, 3), quats (N, 4) (w, x, y, z),
    opacity_logits (N,), sh_dc (N, 1, 3), sh_rest (N, (D+1)^2 - 1, 3)."""

    def __init__(self, tensors, sh_degree):
        super().__init__()
        self.sh_degree = int(sh_degree)
        for name in FIELDS:
            setattr(self, name, nn.Parameter(tensors[name]))

    @classmethod
    def from_points(cls, points, colors, sh_degree, init_opacity, dtype=torch.float32):
        """Gaussians at `points (N, 3)` with RGB `colors (N, 3)` in [0, 1] (or None: grey).

        Isotropic scales of the mean distance to the 3 nearest neighbours, identity
        rotations, opacity `init_opacity`, view-independent colour (higher SH zero).
        """
        points = np.asarray(points, dtype=np.float64)
        n = len(points)
        if n < 2:
            raise ValueError(f"points: need at least 2 points to initialise Gaussians, got {n}")
        k = min(_NEIGHBOURS, n - 1)
        dist, _ = cKDTree(points).query(points, k=k + 1)
        scale = np.maximum(dist[:, 1:].mean(axis=1), 1e-7)
        rgb = np.full((n, 3), 0.5) if colors is None else np.asarray(colors, dtype=np.float64)
        n_rest = (sh_degree + 1) ** 2 - 1
        tensors = {
            "means": torch.tensor(points, dtype=dtype),
            "log_scales": torch.tensor(np.log(scale)[:, None].repeat(3, axis=1), dtype=dtype),
            "quats": torch.tensor(np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), dtype=dtype),
            "opacity_logits": torch.full((n,), float(np.log(init_opacity / (1 - init_opacity))), dtype=dtype),
            "sh_dc": torch.tensor((rgb - 0.5) / C0, dtype=dtype)[:, None, :],
            "sh_rest": torch.zeros(n, n_rest, 3, dtype=dtype),
        }
        return cls(tensors, sh_degree)

    @classmethod
    def empty_like_state(cls, state, sh_degree):
        """Gaussians with the shapes of a saved `state_dict()` (values come from loading it)."""
        return cls({name: torch.zeros_like(state[name]) for name in FIELDS}, sh_degree)

    def __len__(self):
        return self.means.shape[0]

    @property
    def scales(self):
        return torch.exp(self.log_scales)

    @property
    def opacities(self):
        return torch.sigmoid(self.opacity_logits)

    @property
    def sh(self):
        """SH coefficients (N, (D+1)^2, 3), 3DGS order."""
        return torch.cat([self.sh_dc, self.sh_rest], dim=1)

    def tensors(self):
        """The raw parameter tensors by name."""
        return {name: getattr(self, name) for name in FIELDS}

    def set_tensors(self, tensors):
        """Replace every parameter by a new leaf tensor (after densification or pruning)."""
        for name in FIELDS:
            setattr(self, name, nn.Parameter(tensors[name].detach()))
