"""The trainable VeloGauss model: canonical Gaussians, the motion and its resolved spec.

`scene_spec(cfg, metadata)` resolves what the motion computes for a scene, a
`velogauss_core.motion.MotionSpec` (`resolve_motion_spec`, velogauss.model.spec);
`build_model(cfg, spec, points, colors, rng)` makes a fresh `VeloGaussModel` of it.
"""

from velogauss.model.build import build_model, model_from_state, scene_spec
from velogauss.model.velogauss_model import VeloGaussModel
from velogauss.model.spec import ABLATION_SWITCHES, resolve_motion_spec
from velogauss_core.motion import MotionSpec

__all__ = ["ABLATION_SWITCHES", "MotionSpec", "VeloGaussModel", "build_model", "model_from_state",
           "resolve_motion_spec", "scene_spec"]
