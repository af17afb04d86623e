"""The resolution of a model's motion: config + scene effects + ablation → `MotionSpec`, once.

`resolve_motion_spec` turns the training config's model section (what the user configures,
`velogauss.config.ModelConfig`), the scene's declaration (scene.json) and the ablation (paper
Table "ablation") into one frozen `velogauss_core.motion.MotionSpec`, the resolved plan. The
motion (`velogauss.model.motion.gaussians_at`), the model and the training loop read only
this spec; no other layer re-derives which pieces run.

| ablation     | velocity        | ADF | physics losses (GPC) |
|--------------|-----------------|-----|----------------------|
| full         | affine (PDS)    | yes | yes                  |
| no-pds       | MLP v(γ(x), t)  | yes | yes                  |
| no-adf       | affine (PDS)    | no  | yes                  |
| no-gpc       | affine (PDS)    | yes | no                   |
| deform-only  | none            | yes | no  (DefGS-style)    |

Which physics a scene calls for follows from its effects (a subset of
`velogauss_core.motion.EFFECTS`: translation, rotation, gravity, stretch, shear, oscillation,
static) and whether its motion is incompressible, declared in `scene.json` or by the config:

- velocity basis columns (VG-BASIS groups): one group per motion effect, plus the
  translation columns whenever anything moves: rotation, stretch and shear about a
  centre c other than the origin carry the constant term −A c (and gravity needs them
  anyway). Rigid scenes get 6 columns, affine ones up to 12.
- acceleration (VG-ACC): off for uniform translation (Dv/Dt = 0: the transport residual
  is then Newton's first law); on for gravity, oscillation and any rotation, stretch or shear,
  whose material acceleration (centripetal, A² x) is non-zero even at constant
  coefficients. Its columns follow spec/physics.md: translation columns when the velocity
  is translation-only and the acceleration a polynomial, else all 12 (A² leaves the
  velocity's span). Its time dependence: a polynomial in t (VG-ACC) by default, or a
  rigid body's (VG-ACC-RIGID: constant spin, centre under a constant acceleration), as the
  config's `model.acceleration` says ("auto": rigid when the scene's motion is rigid, i.e.
  translation, rotation and gravity only).
- motion patterns: a time network (VG-COEF), rigid bodies under a constant acceleration
  (VG-COEF-RIGID) or oscillators of learned frequency (VG-COEF-HARM), as the config's
  `model.patterns` says. Its "auto" is chosen from the data, before the run, by a backtest
  (velogauss.train.backtest), which writes the choice into the config; one left "auto" here
  (no backtest ran) is the time network. Rigid centres accelerate (3 knots) when the effects
  hold gravity; otherwise they drift uniformly (2 knots). Harmonic patterns bring their own
  acceleration (VG-ACC-HARM, at their frequencies), whatever `model.acceleration` says.
- divergence loss (VG-DIV): only for incompressible motion.
- a scene with no motion effect (`static` alone) builds no velocity at all.

Adding a training scheme: one more value of `Scheme` (velogauss_core.motion), resolved
here, and one branch in `velogauss.model.motion.gaussians_at` (ARCHITECTURE.md).
"""

from dataclasses import dataclass

from velogauss_core.motion import (COLUMN_GROUPS, EFFECTS, MOTION_EFFECTS, UNDECLARED_EFFECTS, MotionSpec,
                                   NetworkSizes, VelocityKind)

# The motion effects a rigid body's acceleration (VG-ACC-RIGID) can follow.
RIGID_EFFECTS = frozenset({"translation", "rotation"})


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


def resolve_motion_spec(model_cfg, metadata: dict | None, max_time: float) -> MotionSpec:
    """The `MotionSpec` of a training config's model section (`velogauss.config.ModelConfig`),
    a scene's `metadata` (a parsed scene.json, or None) and the end of the observed window
    `max_time`.

    `model.effects` / `model.incompressible` "auto" read nothing the scene declares: every
    effect but oscillation (UNDECLARED_EFFECTS) and incompressible motion (what NVFi-style
    methods assume for real scenes); "declared" takes the scene's declaration from `metadata`
    (scene.json), the optional prior, else the same. ValueError when
    `model.acceleration` or `model.patterns` asks "rigid" of a scene that stretches or shears.
    deform-only evaluates its ADF at every t (a DefGS-style model, as DefGS does); the
    others hold it at max_time beyond the window when `model_cfg.adf_clamp_time`.
    """
    scene = _scene_motion(model_cfg, metadata)
    switches = ABLATION_SWITCHES[model_cfg.ablation]
    moving = scene["moving"]
    velocity = switches.velocity if moving else None
    adf = moving and switches.adf
    clamp = model_cfg.adf_clamp_time and model_cfg.ablation != "deform-only"
    # The sizes are NetworkSizes's fields, which ModelConfig inherits (no list of names here).
    sizes = {name: getattr(model_cfg, name) for name in NetworkSizes.__dataclass_fields__}
    carry = model_cfg.scheme == "adf-step" and adf and velocity is not None
    return MotionSpec(
        **sizes,
        mask=scene["mask"],
        acc_mask=scene["acc_mask"],
        acc_form=scene["acc_form"],
        pattern_form=scene["pattern_form"],
        max_time=float(max_time),
        rigid_knots=scene["rigid_knots"],
        effects=scene["effects"],
        moving=moving,
        scheme="adf-step" if carry else "integrate",
        velocity=velocity,
        acceleration=scene["acceleration"],
        integrator=model_cfg.integrator,
        step=float(model_cfg.step),
        adf=adf,
        adf_clamp_time=float(max_time) if clamp else None,
        adf_loss=adf and velocity is not None and not carry,  # scheme (b) renders the ADF's state: x = x*
        physics_loss=switches.gpc and velocity is not None,
        divergence=switches.gpc and velocity is not None and scene["incompressible"],
        carry_until=float(max_time) if carry else None,
        carry_offset=float(model_cfg.carry_offset) if carry else 0.0,
        carry_loss=carry and velocity == "affine",
        query_code="gaussians" if velocity == "affine" else "network",
        # "auto" is resolved by the backtest before this (velogauss.train.backtest); without one it integrates.
        future="integrate" if model_cfg.future == "auto" else model_cfg.future,
    )


def _scene_motion(model_cfg, metadata):
    """What the scene's effects call for (the module docstring's list), before the ablation:
    effects, moving, mask, acceleration, acc_mask, acc_form, pattern_form, rigid_knots and
    incompressible, by name."""
    effects, incompressible = model_cfg.effects, model_cfg.incompressible
    acceleration, patterns = model_cfg.acceleration, model_cfg.patterns
    # "auto" reads nothing the scene declares: every default follows from the data alone.
    if effects == "auto":
        effects = UNDECLARED_EFFECTS
    elif effects == "declared":
        effects = tuple((metadata or {}).get("effects", UNDECLARED_EFFECTS))
    if incompressible == "auto":
        incompressible = True
    elif incompressible == "declared":
        incompressible = bool((metadata or {}).get("incompressible", True))
    effects = tuple(e for e in EFFECTS if e in effects)
    groups = {e for e in effects if e in MOTION_EFFECTS}
    if groups or "gravity" in effects:
        groups.add("translation")
    moving = bool(groups)
    oscillates = "oscillation" in effects
    has_acceleration = moving and ("gravity" in effects or oscillates or bool(groups - {"translation"}))
    rigid = groups <= RIGID_EFFECTS
    for key, value, other in (("acceleration", acceleration, "poly"), ("patterns", patterns, "mlp")):
        if value == "rigid" and not rigid:
            raise ValueError(f"model.{key}: 'rigid' cannot follow the effects {sorted(groups - RIGID_EFFECTS)} "
                             f"(a rigid body neither stretches nor shears); use '{other}' or 'auto'")
    if patterns == "auto":  # not chosen by a backtest (velogauss.train.backtest): the time network
        patterns = "mlp"
    form = ("rigid" if rigid else "poly") if acceleration == "auto" else acceleration
    # A moving harmonic pattern always has an acceleration (its reversal).
    form = "harmonic" if patterns == "harmonic" else form if has_acceleration else "poly"
    has_acceleration = has_acceleration or (moving and patterns == "harmonic")
    if not has_acceleration:
        acc_mask = (False,) * 12
    elif groups == {"translation"} and form == "poly":
        acc_mask = _columns({"translation"})
    else:
        # The rigid form's Omega^2 lies on the stretch and shear columns: masking them while
        # keeping its -Omega^2 c(t) translation term would not be a rigid body's acceleration.
        acc_mask = (True,) * 12
    return {"effects": effects, "moving": moving, "mask": _columns(groups), "acceleration": has_acceleration,
            "acc_mask": acc_mask, "acc_form": form, "pattern_form": patterns,
            # Without gravity nothing accelerates a body's centre: it drifts uniformly, and a
            # third knot would only let noise bend its path.
            "rigid_knots": 3 if "gravity" in effects else 2, "incompressible": moving and bool(incompressible)}


def _columns(groups):
    selected = {c for g in groups for c in COLUMN_GROUPS[g]}
    return tuple(c in selected for c in range(12))
