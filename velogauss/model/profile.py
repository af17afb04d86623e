"""Which physics a scene calls for: its effect profile decides what the model builds and computes.

A scene declares its effects (a subset of `velogauss.scenes.EFFECTS`: translation,
rotation, gravity, stretch, shear, static) and whether its motion is incompressible, in
`scene.json` or on the command line. From them:

- velocity basis columns (VG-BASIS groups): one group per motion effect, plus the
  translation columns whenever anything moves: rotation, stretch and shear about a
  centre c other than the origin carry the constant term −A c (and gravity needs them
  anyway). Rigid scenes get 6 columns, affine ones up to 12.
- acceleration (VG-ACC): off for uniform translation (Dv/Dt = 0: the transport residual
  is then Newton's first law); on for gravity and for any rotation, stretch or shear,
  whose material acceleration (centripetal, A² x) is non-zero even at constant
  coefficients. Its columns follow spec/physics.md: translation columns when the velocity
  is translation-only, else all 12 (A² leaves the velocity's span).
- divergence loss (VG-DIV): only for incompressible motion.
- a scene with no motion effect (`static` alone) builds no velocity at all.
"""

from dataclasses import dataclass

from velogauss.config import EFFECTS as ALL_EFFECTS
from velogauss_ref.motion.basis import COLUMN_GROUPS

MOTION_EFFECTS = ("translation", "rotation", "stretch", "shear")


@dataclass(frozen=True)
class MotionProfile:
    """What the motion model computes for one scene.

    effects: the resolved effect list; moving: any motion at all; mask: 12 bools, the
    velocity's basis columns; acceleration: the VG-ACC term is built; acc_mask: 12 bools,
    its columns; divergence: the VG-DIV loss is used.
    """

    effects: tuple
    moving: bool
    mask: tuple
    acceleration: bool
    acc_mask: tuple
    divergence: bool

    @property
    def n_columns(self):
        """Number of basis columns the velocity uses."""
        return sum(self.mask)


def resolve_profile(effects, incompressible, metadata=None):
    """The `MotionProfile` of `effects` / `incompressible` ("auto" or explicit values).

    "auto" takes the scene's declaration from `metadata` (a parsed scene.json), else every
    effect and incompressible motion (what NVFi-style methods assume for real scenes).
    """
    if effects == "auto":
        effects = tuple((metadata or {}).get("effects", ALL_EFFECTS))
    if incompressible == "auto":
        incompressible = bool((metadata or {}).get("incompressible", True))
    effects = tuple(e for e in ALL_EFFECTS if e in effects)
    groups = {e for e in effects if e in MOTION_EFFECTS}
    if groups or "gravity" in effects:
        groups.add("translation")
    mask = _columns(groups)
    moving = bool(groups)
    acceleration = moving and ("gravity" in effects or bool(groups - {"translation"}))
    if not acceleration:
        acc_mask = (False,) * 12
    elif groups == {"translation"}:
        acc_mask = _columns({"translation"})
    else:
        acc_mask = (True,) * 12
    return MotionProfile(effects=effects, moving=moving, mask=mask, acceleration=acceleration, acc_mask=acc_mask,
                         divergence=moving and bool(incompressible))


def _columns(groups):
    selected = {c for g in groups for c in COLUMN_GROUPS[g]}
    return tuple(c in selected for c in range(12))
