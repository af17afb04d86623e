"""Which physics a scene calls for: its effect profile decides what the model builds and computes.

A scene declares its effects (a subset of `velogauss_core.motion.EFFECTS`: translation,
rotation, gravity, stretch, shear, oscillation, static) and whether its motion is incompressible, in
`scene.json` or on the command line. From them:

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
- motion patterns: a time network (VG-COEF), or for a scene whose motion is rigid, rigid
  bodies under a constant acceleration (VG-COEF-RIGID), or for a scene that declares
  oscillation, oscillators of learned frequency (VG-COEF-HARM), as the config's
  `model.patterns` says ("auto": harmonic when the scene oscillates, else rigid when its
  motion is rigid, else the time network). Rigid centres accelerate (3 knots) only when the
  scene declares gravity; otherwise they drift uniformly (2 knots). Harmonic patterns bring
  their own acceleration (VG-ACC-HARM, at their frequencies), whatever `model.acceleration` says.
- divergence loss (VG-DIV): only for incompressible motion.
- how renders composite (VG-RENDER's mode), the config's `model.rasterize_mode`: kept with
  the profile, which every checkpoint stores, so that a model renders as it was trained.

`resolve_profile`'s keyword defaults are the config's (`velogauss.config.ModelConfig`).
- a scene with no motion effect (`static` alone) builds no velocity at all.
"""

from dataclasses import dataclass

from velogauss_core.motion import COLUMN_GROUPS, EFFECTS, MOTION_EFFECTS, UNDECLARED_EFFECTS

# The motion effects a rigid body's acceleration (VG-ACC-RIGID) can follow.
RIGID_EFFECTS = frozenset({"translation", "rotation"})


@dataclass(frozen=True)
class MotionProfile:
    """What the motion model computes for one scene.

    effects: the resolved effect list; moving: any motion at all; mask: 12 bools, the
    velocity's basis columns; acceleration: the VG-ACC term is built; acc_mask: 12 bools,
    its columns; acc_form: its time dependence, "poly" (VG-ACC), "rigid" (VG-ACC-RIGID) or
    "harmonic" (VG-ACC-HARM); divergence: the VG-DIV loss is used; pattern_form: the motion
    patterns' time dependence, "mlp" (VG-COEF), "rigid" (VG-COEF-RIGID) or "harmonic"
    (VG-COEF-HARM); rigid_knots: VG-COEF-RIGID's knots per centre, 3 (under gravity) or 2
    (uniform drift); rasterize_mode: VG-RENDER's mode.
    """

    effects: tuple
    moving: bool
    mask: tuple
    acceleration: bool
    acc_mask: tuple
    divergence: bool
    acc_form: str
    pattern_form: str
    rigid_knots: int
    rasterize_mode: str

    @property
    def n_columns(self):
        """Number of basis columns the velocity uses."""
        return sum(self.mask)


def resolve_profile(effects, incompressible, metadata=None, acceleration="poly", patterns="auto",
                    rasterize_mode="antialiased"):
    """The `MotionProfile` of `effects` / `incompressible` / `acceleration` / `patterns` ("auto"
    or explicit values) and `rasterize_mode`.

    "auto" takes the scene's declaration from `metadata` (a parsed scene.json), else every
    effect but oscillation (UNDECLARED_EFFECTS) and incompressible motion (what NVFi-style
    methods assume for real scenes).
    `acceleration` (config `model.acceleration`): "poly" (VG-ACC), "rigid" (VG-ACC-RIGID), or
    "auto", rigid when the motion effects are rigid ones, else poly.
    `patterns` (config `model.patterns`): "mlp" (VG-COEF), "rigid" (VG-COEF-RIGID), "harmonic"
    (VG-COEF-HARM), or "auto": harmonic when the effects include oscillation, else rigid when
    the motion effects are rigid ones, else mlp. Harmonic patterns take the harmonic
    acceleration (VG-ACC-HARM), which needs their frequencies, whatever `acceleration` says.
    ValueError when "rigid" is asked of a scene that stretches or shears.
    `rasterize_mode` (config `model.rasterize_mode`): "classic" or "antialiased"
    (velogauss_core.rendering), taken as it is.
    The keyword defaults are the config's.
    """
    if effects == "auto":
        effects = tuple((metadata or {}).get("effects", UNDECLARED_EFFECTS))
    if incompressible == "auto":
        incompressible = bool((metadata or {}).get("incompressible", True))
    effects = tuple(e for e in EFFECTS if e in effects)
    groups = {e for e in effects if e in MOTION_EFFECTS}
    if groups or "gravity" in effects:
        groups.add("translation")
    mask = _columns(groups)
    moving = bool(groups)
    oscillates = "oscillation" in effects
    has_acceleration = moving and ("gravity" in effects or oscillates or bool(groups - {"translation"}))
    rigid = groups <= RIGID_EFFECTS
    for key, value, other in (("acceleration", acceleration, "poly"), ("patterns", patterns, "mlp")):
        if value == "rigid" and not rigid:
            raise ValueError(f"model.{key}: 'rigid' cannot follow the effects {sorted(groups - RIGID_EFFECTS)} "
                             f"(a rigid body neither stretches nor shears); use '{other}' or 'auto'")
    if patterns == "auto":
        patterns = "harmonic" if oscillates and moving else "rigid" if rigid and moving else "mlp"
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
    return MotionProfile(effects=effects, moving=moving, mask=mask, acceleration=has_acceleration,
                         acc_mask=acc_mask, divergence=moving and bool(incompressible),
                         acc_form=form, pattern_form=patterns,
                         # Without gravity nothing accelerates a body's centre: it drifts
                         # uniformly, and a third knot would only let noise bend its path.
                         rigid_knots=3 if "gravity" in effects else 2, rasterize_mode=rasterize_mode)


def _columns(groups):
    selected = {c for g in groups for c in COLUMN_GROUPS[g]}
    return tuple(c in selected for c in range(12))
