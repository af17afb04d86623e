"""Assemble a `VeloGaussModel` from a training config and a scene.

The ablations of the paper (Table "ablation") map to switches here:

| ablation     | velocity        | ADF | physics losses (GPC) |
|--------------|-----------------|-----|----------------------|
| full         | affine (PDS)    | yes | yes                  |
| no-pds       | MLP v(γ(x), t)  | yes | yes                  |
| no-adf       | affine (PDS)    | no  | yes                  |
| no-gpc       | affine (PDS)    | yes | no                   |
| deform-only  | none            | yes | no  (DefGS-style)    |
"""

from dataclasses import dataclass

import numpy as np

from velogauss.model.dynamic import VeloGaussModel
from velogauss.model.gaussians import Gaussians
from velogauss.model.motion import MotionModel, motion_config
from velogauss.model.profile import MotionProfile, resolve_profile


@dataclass(frozen=True)
class Switches:
    """The ablation switches: velocity kind ("affine", "mlp" or None), ADF, GPC."""

    velocity: object
    adf: bool
    gpc: bool


ABLATION_SWITCHES = {
    "full": Switches("affine", True, True),
    "no-pds": Switches("mlp", True, True),
    "no-adf": Switches("affine", False, True),
    "no-gpc": Switches("affine", True, False),
    "deform-only": Switches(None, True, False),
}


def build_model(cfg, profile, points, colors, rng):
    """A fresh model for `cfg` (velogauss.config.Config) and the scene's `profile`.

    points (M, 3) / colors (M, 3) or None: the initial Gaussian centres and colours;
    rng: NumPy Generator for the initial motion weights.
    """
    m = cfg.model
    gaussians = Gaussians.from_points(points, colors, m.sh_degree, m.init_opacity)
    return _assemble(cfg, profile, gaussians, rng)


def model_from_state(cfg, profile, state):
    """A model with the shapes of a saved `state_dict()` `state` (load it afterwards)."""
    prefix = "gaussians."
    gstate = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
    gaussians = Gaussians.empty_like_state(gstate, cfg.model.sh_degree)
    return _assemble(cfg, profile, gaussians, np.random.default_rng(0))


def scene_profile(cfg, metadata):
    """The `MotionProfile` of the config's effects for a scene with `metadata` (scene.json or None)."""
    return resolve_profile(cfg.model.effects, cfg.model.incompressible, metadata)


def profile_from_dict(values):
    """Inverse of `dataclasses.asdict(profile)` (lists back to tuples)."""
    return MotionProfile(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _assemble(cfg, profile, gaussians, rng):
    m = cfg.model
    switches = ABLATION_SWITCHES[m.ablation]
    motion = None
    if profile.moving:
        motion = MotionModel(motion_config(m, profile), profile, switches.velocity, switches.adf, m.integrator, m.step,
                             rng)
    # deform-only is a DefGS-style model: its deformation network is evaluated at every t.
    clamp = m.adf_clamp_time and m.ablation != "deform-only"
    return VeloGaussModel(gaussians, motion, cfg.data.max_time, adf_clamp_time=clamp, scheme=m.scheme)
