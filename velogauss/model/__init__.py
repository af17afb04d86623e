"""The trainable VeloGauss model: canonical Gaussians, the motion model and its effect profile.

`build_model(cfg, profile, points, colors, rng)` makes a fresh `VeloGaussModel`;
`scene_profile(cfg, metadata)` resolves which physics a scene calls for.
"""

from velogauss.model.build import ABLATION_SWITCHES, build_model, model_from_state, scene_profile
from velogauss.model.dynamic import VeloGaussModel
from velogauss.model.profile import MotionProfile, resolve_profile

__all__ = ["ABLATION_SWITCHES", "MotionProfile", "VeloGaussModel", "build_model", "model_from_state",
           "resolve_profile", "scene_profile"]
