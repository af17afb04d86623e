"""Assemble a `VeloGaussModel` from a training config and a scene.

The config's model section, the scene's `MotionProfile` and the ablation are resolved once
into a `MotionSpec` (velogauss.model.spec); the model's parameters are laid out by it.
"""

import numpy as np

from velogauss.model.velogauss_model import VeloGaussModel
from velogauss.model.gaussians import Gaussians
from velogauss.model.motion import MotionParameters
from velogauss.model.profile import MotionProfile, resolve_profile
from velogauss.model.spec import resolve_motion_spec


def build_model(cfg, profile: MotionProfile, points, colors, rng: np.random.Generator) -> VeloGaussModel:
    """A fresh model for `cfg` (velogauss.config.Config) and the scene's `profile`.

    points (M, 3) / colors (M, 3) or None: the initial Gaussian centres and colours;
    rng: NumPy Generator of the initial motion weights (`velogauss_core.motion.init_motion_params`).
    """
    m = cfg.model
    gaussians = Gaussians.from_points(points, colors, m.sh_degree, m.init_opacity)
    return _assemble(cfg, profile, gaussians, rng)


def model_from_state(cfg, profile: MotionProfile, state: dict) -> VeloGaussModel:
    """A model with the shapes of a saved `state_dict()` `state` (load it afterwards)."""
    prefix = "gaussians."
    gstate = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
    gaussians = Gaussians.empty_like_state(gstate, cfg.model.sh_degree)
    # The drawn values are overwritten by loading; a private generator leaves the run's untouched.
    return _assemble(cfg, profile, gaussians, np.random.default_rng(0))


def scene_profile(cfg, metadata: dict | None) -> MotionProfile:
    """The `MotionProfile` of the config's effects for a scene with `metadata` (scene.json or None)."""
    return resolve_profile(cfg.model.effects, cfg.model.incompressible, metadata, cfg.model.acceleration,
                           cfg.model.patterns, cfg.model.rasterize_mode)


def profile_from_dict(values: dict) -> MotionProfile:
    """Inverse of `dataclasses.asdict(profile)` (lists back to tuples)."""
    return MotionProfile(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _assemble(cfg, profile, gaussians, rng):
    spec = resolve_motion_spec(cfg.model, profile, cfg.data.max_time)
    motion = MotionParameters(spec, rng) if spec.moving else None
    return VeloGaussModel(gaussians, motion, spec, profile.rasterize_mode)
