"""Assemble a `VeloGaussModel` from a training config and a scene.

The config's model section, the scene's declared effects and the ablation are resolved once
into a `MotionSpec` (`scene_spec`, velogauss.model.spec); the model's parameters are laid out
by it.
"""

import numpy as np

from velogauss.model.velogauss_model import VeloGaussModel
from velogauss.model.gaussians import Gaussians
from velogauss.model.motion import MotionParameters
from velogauss.model.spec import resolve_motion_spec
from velogauss_core.motion import MotionSpec


def build_model(cfg, spec: MotionSpec, points, colors, rng: np.random.Generator) -> VeloGaussModel:
    """A fresh model for `cfg` (velogauss.config.Config) and its resolved `spec` (`scene_spec`).

    points (M, 3) / colors (M, 3) or None: the initial Gaussian centres and colours;
    rng: NumPy Generator of the initial motion weights (`velogauss_core.motion.init_motion_params`).
    """
    m = cfg.model
    gaussians = Gaussians.from_points(points, colors, m.sh_degree, m.init_opacity)
    return _assemble(cfg, spec, gaussians, rng)


def model_from_state(cfg, spec: MotionSpec, state: dict, forecast_spec: MotionSpec | None = None) -> VeloGaussModel:
    """A model with the shapes of a saved `state_dict()` `state` (load it afterwards);
    forecast_spec: the spec of the forecast it holds (`VeloGaussModel.set_forecast`), if any."""
    prefix = "gaussians."
    gstate = {k[len(prefix):]: v for k, v in state.items() if k.startswith(prefix)}
    gaussians = Gaussians.empty_like_state(gstate, cfg.model.sh_degree)
    # The drawn values are overwritten by loading; a private generator leaves the run's untouched.
    model = _assemble(cfg, spec, gaussians, np.random.default_rng(0))
    if forecast_spec is not None:
        model.set_forecast(MotionParameters(forecast_spec, np.random.default_rng(0)))
    return model


def scene_spec(cfg, metadata: dict | None) -> MotionSpec:
    """The `MotionSpec` of the config `cfg` for a scene with `metadata` (scene.json or None)."""
    return resolve_motion_spec(cfg.model, metadata, cfg.data.max_time)


def _assemble(cfg, spec, gaussians, rng):
    motion = MotionParameters(spec, rng) if spec.moving else None
    # The mode comes from the run's own config, which a resume may not change.
    return VeloGaussModel(gaussians, motion, spec, cfg.model.rasterize_mode)
