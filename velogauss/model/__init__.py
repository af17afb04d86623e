"""The trainable VeloGauss model: canonical Gaussians, the motion and its resolved spec.

`build_model(cfg, profile, points, colors, rng)` makes a fresh `VeloGaussModel`;
`scene_profile(cfg, metadata)` resolves which physics a scene calls for, and
`resolve_motion_spec` what the motion computes (velogauss.model.spec).
"""

from velogauss.model.build import build_model, model_from_state, scene_profile
from velogauss.model.velogauss_model import VeloGaussModel
from velogauss.model.profile import MotionProfile, resolve_profile
from velogauss.model.spec import ABLATION_SWITCHES, MotionSpec, resolve_motion_spec

__all__ = ["ABLATION_SWITCHES", "MotionProfile", "MotionSpec", "VeloGaussModel", "build_model", "model_from_state",
           "resolve_motion_spec", "resolve_profile", "scene_profile"]
