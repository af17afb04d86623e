"""A rigid pattern's centre anchored on the body's centre of mass (VG-COEF-RIGID, "Centre").

A rigid pattern `v = ω × (x − c(t)) + ċ(t)` with `c(t)` a parabola moves a body in free
flight exactly when `c(t)` is its centre of mass, the one material point that moves on a
parabola. Any other material point `p(t)` of the body gives the same field in the form
`ω × (x − p(t)) + ṗ(t)`, but its path turns with the body. Inside the observed window a
parabola follows such a point to within a fraction of a pixel, which the ADF's correction
absorbs, so the images hardly tell the points apart, and training leaves the knots on a point
off the axis through the body's centre. Past the window the parabola and the point part, and
the future frames drift (benchmarks/FIDELITY.md, section 0a).

`anchor_centres` (config `model.rigid_centre = "hull"`) places every pattern's knots, once,
when the motion starts training (the warm-up's end, when the Gaussians have fitted the
t = 0 frames), at the centroid of the volume inside the convex hull of the moving Gaussians
at least RIGID_HULL_OPACITY times as opaque as the most opaque one: the centre of mass of a
uniform convex body, which the surface's Gaussians bound whatever their density on it.
`first_knot_mask` then holds the first knot, the centre at t = 0, there; the other knots and
the spin train as before. One centre for every pattern is one body: "auto" anchors only where
the mixing starts uniform, the scenes with one body to track (velogauss.train.mixing), and
only a centre that moves on a parabola (gravity, 3 knots), whose curvature is what lets it
follow a turning point: a centre that drifts on a line (2 knots) cannot, and is better
learned (FIDELITY.md, section 0a).
"""

import numpy as np
import torch
from scipy.spatial import Delaunay, QhullError

from velogauss.train.mixing import resolve_mixing_init
from velogauss_core.constants import RIGID_HULL_OPACITY


def resolve_rigid_centre(choice, spec, mixing_init):
    """"hull" (anchored) or "learned" (trained from the images alone) for the config's
    `model.rigid_centre` ("auto" or "hull"), a `MotionSpec` and the config's
    `model.mixing_init`: "auto" is "hull" for rigid patterns whose centres move on a parabola
    (3 knots: the scene declares gravity) and whose mixing starts uniform (one body), else
    "learned". "hull" without rigid patterns raises ValueError."""
    rigid = spec.pattern_form == "rigid"
    if choice == "hull" and not rigid:
        raise ValueError(f"model.rigid_centre: 'hull' anchors rigid motion patterns, and this scene's patterns "
                         f"are {spec.pattern_form!r}; use 'auto'")
    if choice == "hull":
        return choice
    one_body = resolve_mixing_init(mixing_init, spec) == "uniform"
    return "hull" if rigid and spec.rigid_knots == 3 and one_body else "learned"


def hull_centroid(points):
    """Centroid (3,) of the volume inside the convex hull of `points` (M, 3) NumPy float64:
    the tetrahedra of their Delaunay triangulation, weighted by volume. Points that span no
    volume (fewer than 4, or flat) give their mean."""
    points = np.asarray(points, dtype=np.float64)
    try:
        tetrahedra = points[Delaunay(points).simplices]  # [T, 4, 3]
    except (QhullError, ValueError):
        return points.mean(0)
    volumes = np.abs(np.linalg.det(tetrahedra[:, 1:] - tetrahedra[:, :1])) / 6.0
    if not volumes.sum() > 0:
        return points.mean(0)
    return (volumes[:, None] * tetrahedra.mean(1)).sum(0) / volumes.sum()


@torch.no_grad()
def anchor_centres(model):
    """Set every knot of each rigid pattern of `model` (a `VeloGaussModel` whose
    spec.pattern_form is "rigid") to the hull centroid of its moving Gaussians at
    least RIGID_HULL_OPACITY times as opaque as the most opaque. Returns that centre (3,) NumPy.

    Raises ValueError unless the patterns are still (ω = 0, each pattern's knots equal):
    a still pattern is still wherever its centre is, so the motion does not change (up to
    the float32 rounding of ċ, the knots times Lagrange weights that cancel); or when no
    Gaussian moves."""
    if not model.spec.rigid_patterns:
        raise ValueError("model: anchor_centres needs rigid motion patterns (model.patterns = 'rigid')")
    B = model.motion.time
    omega, first, *rest = B.split(3, dim=-1)
    if bool(omega.any()) or any(not torch.equal(first, knot) for knot in rest):
        raise ValueError("model.motion.time: the rigid patterns have started moving; their centres can only be "
                         "anchored while they are still (omega = 0, equal knots)")
    g = model.gaussians
    if not bool(model.moving.any()):
        raise ValueError("model.moving: no Gaussian moves, so there is no body to anchor the rigid patterns' centres on")
    opacity = g.opacities.reshape(-1)
    keep = model.moving & (opacity >= RIGID_HULL_OPACITY * opacity[model.moving].max())
    centre = hull_centroid(g.means[keep].detach().cpu().numpy())
    B[:, 3:] = torch.as_tensor(centre, dtype=B.dtype, device=B.device).repeat(len(rest) + 1)
    return centre


def first_knot_mask(B):
    """A tensor like B (K, 3 + 3 n): 0 on the first knot's columns (the centre at t = 0),
    1 elsewhere. Training multiplies B's gradient by it, so Adam never moves that knot (its
    moments stay 0, and so does its step)."""
    mask = torch.ones_like(B)
    mask[:, 3:6] = 0.0
    return mask
