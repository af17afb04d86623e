"""The resolved description of a model's motion: config + scene profile + ablation, once.

`resolve_motion_spec` turns the training config's model section, the scene's
`MotionProfile` and the ablation (paper Table "ablation") into one frozen `MotionSpec`.
The motion (`velogauss.model.motion.gaussians_at`), the model and the training loop read
only this spec; no other layer re-derives which pieces run.

| ablation     | velocity        | ADF | physics losses (GPC) |
|--------------|-----------------|-----|----------------------|
| full         | affine (PDS)    | yes | yes                  |
| no-pds       | MLP v(γ(x), t)  | yes | yes                  |
| no-adf       | affine (PDS)    | no  | yes                  |
| no-gpc       | affine (PDS)    | yes | no                   |
| deform-only  | none            | yes | no  (DefGS-style)    |

Adding a training scheme: one more value of `Scheme` (velogauss_core.motion), resolved
here, and one branch in `velogauss.model.motion.gaussians_at` (ARCHITECTURE.md).
"""

import dataclasses
from dataclasses import dataclass

from velogauss.model.profile import MotionProfile
# `Scheme` ("integrate" (a), "adf-step" (b)) is defined once in velogauss_core.motion, where
# the config (which this package imports) can type its key.
from velogauss_core.motion import Integrator, MotionConfig, MotionSizes, QueryCode, Scheme, VelocityKind


@dataclass(frozen=True)
class _Switches:
    velocity: VelocityKind | None
    adf: bool
    gpc: bool


# The paper's ablations as switches (module docstring's table).
ABLATION_SWITCHES: dict[str, _Switches] = {
    "full": _Switches("affine", True, True),
    "no-pds": _Switches("mlp", True, True),
    "no-adf": _Switches("affine", False, True),
    "no-gpc": _Switches("affine", True, False),
    "deform-only": _Switches(None, True, False),
}


@dataclass(frozen=True)
class MotionSpec:
    """What the motion of one model computes, resolved once (see the module docstring).

    scheme: how positions come from the velocity (`Scheme`); "adf-step" only where there is
      a velocity and an ADF (it carries the ADF's state), else resolved to "integrate";
    moving: the scene moves at all (False: a static scene, no motion parameters, every
      other field is then off);
    velocity: "affine" (PDS: Phi(x) w(t, z) over config.mask, VG-VEL), "mlp" (no-pds) or None
      (deform-only: x* = x0);
    config: network sizes, the basis masks (velocity mask, acceleration mask) and the
      acceleration's form;
    acceleration: the acceleration (VG-ACC or VG-ACC-RIGID, config.acc_form) is a parameter
      (else Q = 0);
    integrator, step: VG-INTEG's method and largest step in normalised time;
    adf: the ADF residual is built and applied (VG-ADF);
    adf_clamp_time: the ADF's input time is min(t, this), or None (evaluated at every t);
    adf_loss: the L2 penalty on the ADF's displacement |x - x*|^2 is on (ADF on top of a
      velocity, scheme "integrate"; under "adf-step" x = x*, the penalty would be 0);
    physics_loss: the VG-LOSS-PHYS transport residual on collocation points is on (GPC);
    divergence: the VG-DIV term of the physics loss is on (incompressible motion);
    carry_until: scheme "adf-step": the end of the ADF's window (max_time), where beyond it
      the velocity alone carries the ADF's state (VG-CARRY); None for "integrate";
    carry_offset: scheme "adf-step": |t - t_start| of VG-CARRY in training (0 otherwise);
    carry_loss: VG-LOSS-CARRY (the affine velocity fitted to the ADF's paths) can be on:
      scheme "adf-step" with the affine velocity; its weight is train.lambda_carry;
    query_code: where a material point that is not a Gaussian takes its mixing weights:
      "gaussians" from its nearest Gaussians' (VG-FIELD-GAUSS) under the affine velocity,
      "network" elsewhere (the velocity MLP of no-pds reads the point itself; no mixing weights).
    """

    scheme: Scheme
    moving: bool
    velocity: VelocityKind | None
    config: MotionConfig
    acceleration: bool
    integrator: Integrator
    step: float
    adf: bool
    adf_clamp_time: float | None
    adf_loss: bool
    physics_loss: bool
    divergence: bool
    carry_until: float | None
    carry_offset: float
    carry_loss: bool
    query_code: QueryCode

    @property
    def rigid_patterns(self) -> bool:
        """The affine velocity's motion patterns are VG-COEF-RIGID's rigid bodies (`params["time"]`
        is their B, a (K, 3 + 3 n) tensor)."""
        return self.velocity == "affine" and self.config.pattern_form == "rigid"

    def without_adf(self) -> "MotionSpec":
        """This spec with the ADF skipped: what training runs before the ADF starts learning
        (its last layer is still zero then, so skipping it is exactly the identity). Scheme
        "adf-step" carries the ADF's state, so without the ADF it is "integrate"."""
        return dataclasses.replace(self, adf=False, scheme="integrate", carry_until=None, carry_offset=0.0,
                                   carry_loss=False)


def resolve_motion_spec(model_cfg, profile: MotionProfile, max_time: float) -> MotionSpec:
    """The `MotionSpec` of a training config's model section (`velogauss.config.ModelConfig`),
    a scene's `profile` and the end of the observed window `max_time`.

    deform-only evaluates its ADF at every t (a DefGS-style model, as DefGS does); the
    others hold it at max_time beyond the window when `model_cfg.adf_clamp_time`.
    """
    switches = ABLATION_SWITCHES[model_cfg.ablation]
    moving = bool(profile.moving)
    velocity = switches.velocity if moving else None
    adf = moving and switches.adf
    clamp = model_cfg.adf_clamp_time and model_cfg.ablation != "deform-only"
    # The sizes are MotionSizes's fields, which ModelConfig inherits (no list of names here).
    sizes = {f.name: getattr(model_cfg, f.name) for f in dataclasses.fields(MotionSizes)}
    carry = model_cfg.scheme == "adf-step" and adf and velocity is not None
    return MotionSpec(
        scheme="adf-step" if carry else "integrate",
        moving=moving,
        velocity=velocity,
        config=MotionConfig(**sizes, mask=profile.mask, acc_mask=profile.acc_mask, acc_form=profile.acc_form,
                            pattern_form=profile.pattern_form, max_time=float(max_time),
                            rigid_knots=profile.rigid_knots),
        acceleration=moving and bool(profile.acceleration),
        integrator=model_cfg.integrator,
        step=float(model_cfg.step),
        adf=adf,
        adf_clamp_time=float(max_time) if clamp else None,
        adf_loss=adf and velocity is not None and not carry,  # scheme (b) renders the ADF's state: x = x*
        physics_loss=switches.gpc and velocity is not None,
        divergence=switches.gpc and velocity is not None and bool(profile.divergence),
        carry_until=float(max_time) if carry else None,
        carry_offset=float(model_cfg.carry_offset) if carry else 0.0,
        carry_loss=carry and velocity == "affine",
        query_code="gaussians" if velocity == "affine" else "network",
    )

