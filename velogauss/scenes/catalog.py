"""The named synthetic scenes, and rebuilding a generated scene's ground truth.

World axes: z up, gravity along −z; objects of about one unit near the origin, seen from
about 4 units away. Each scene declares the physical `effects` its motion needs, named
after the VG-BASIS column groups (`translation`, `rotation`, `stretch`, `shear`) plus
`gravity` (a non-zero acceleration), `oscillation` (the motion repeats) and `static` (a body
that never moves):

- `spin`: a checkered box spinning about a tilted axis through the origin. rotation.
- `toss`: a spinning checkered box thrown up and falling back under gravity; it leaves
  the first quarter of the view at t = 0 and lands back at the same height at t = 1, so
  the future window t > 0.75 is its accelerating fall. translation, rotation, gravity.
- `multi`: a translating (not rolling) ball, a box spinning in place and a tumbling,
  drifting ellipsoid over a static checkered ground. translation, rotation, static.
- `stretch`: a cube stretched along x as `diag(e^{kt}, e^{−kt/2}, e^{−kt/2})`
  (volume-preserving). stretch, incompressible.
- `shear`: a cube under pure shear in the x–z plane, `exp(γ t (e_x e_zᵀ + e_z e_xᵀ))`:
  the symmetric, trace-free velocity gradient that the VG-BASIS `shear` columns span
  (a simple shear `x += γ t z` would also need the `rotation` columns, as it is pure
  shear plus a spin). Volume-preserving. shear, incompressible.
- `pulse`: a cube whose stretch along x oscillates, `exp(sin(ω t) diag(k, −k/2, −k/2))`
  with a period of 2/3: the motion reverses inside the observed window and again in the
  future (it is back at its canonical shape at t = 1), which no motion extrapolated as a
  polynomial in t can follow. stretch, oscillation, incompressible.
- `grow`: a sphere expanding uniformly as `e^{kt}`: the one compressible scene, so that
  `incompressible = false` is exercised. stretch.

Rigid motions preserve volume, so `spin`, `toss` and `multi` are incompressible too.
`DEFAULT_SCENE` is `toss`: one small object whose motion combines translation, rotation
and gravity, so the future frames separate physically consistent extrapolation (a
parabola) from constant-velocity guesses, yet it trains in minutes on a CPU.
"""

import inspect
import json
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from velogauss.data.errors import DataError
from velogauss.scenes.bodies import Body, Texture
from velogauss.scenes.trajectories import LinearFlowMotion, PeriodicFlowMotion, RigidMotion, StaticMotion
from velogauss.scenes.scene import AnalyticScene

_ORANGE, _BLUE = (0.95, 0.55, 0.15), (0.15, 0.35, 0.85)
_RED, _YELLOW = (0.85, 0.2, 0.2), (0.95, 0.85, 0.25)
_GREEN, _WHITE = (0.2, 0.7, 0.35), (0.95, 0.95, 0.95)
_PURPLE, _TEAL = (0.6, 0.3, 0.75), (0.2, 0.75, 0.75)
_GREY_DARK, _GREY_LIGHT = (0.45, 0.45, 0.45), (0.8, 0.8, 0.8)


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _tilt(rotvec):
    return Rotation.from_rotvec(rotvec).as_matrix()


def spin():
    """A checkered box spinning at 3 rad per unit time about a tilted axis through the origin."""
    box = Body("box", "box", centre=(0.0, 0.0, 0.0), size=(0.55, 0.4, 0.3), rotation=_tilt((0.3, -0.2, 0.4)),
               texture=Texture("checker", (_ORANGE, _BLUE), frequency=2.0),
               motion=RigidMotion(centre=(0.0, 0.0, 0.0), omega=3.0 * _unit((0.2, 0.3, 1.0))))
    return AnalyticScene("spin", [box], effects=["rotation"], incompressible=True)


def toss():
    """A box spinning at 2 rad per unit time, thrown from (−0.5, 0, −0.5) with velocity (1, 0, 4)
    under gravity 8.

    The centre follows `z = −0.5 + 4 t − 4 t²`: apex 0.5 at t = 0.5, back to −0.5 at
    t = 1, while x drifts from −0.5 to 0.5, so the box stays in view over [0, 1].
    """
    box = Body("box", "box", centre=(-0.5, 0.0, -0.5), size=(0.42, 0.3, 0.24), rotation=_tilt((0.2, 0.3, 0.0)),
               texture=Texture("checker", (_RED, _YELLOW), frequency=2.0),
               motion=RigidMotion(centre=(-0.5, 0.0, -0.5), omega=2.0 * _unit((1.0, 0.4, 0.2)),
                                  velocity=(1.0, 0.0, 4.0), gravity=(0.0, 0.0, -8.0)))
    return AnalyticScene("toss", [box], effects=["translation", "rotation", "gravity"], incompressible=True)


def multi():
    """Three bodies with different rigid motions above a static ground square at z = −0.7."""
    ball = Body("ball", "ellipsoid", centre=(-0.7, -0.5, -0.35), size=(0.3, 0.3, 0.3), rotation=np.eye(3),
                texture=Texture("stripes", (_RED, _YELLOW), axis=0, frequency=3.0),
                motion=RigidMotion(centre=(-0.7, -0.5, -0.35), velocity=(1.0, 0.4, 0.0)))
    cube = Body("cube", "box", centre=(0.7, 0.6, -0.45), size=(0.25, 0.25, 0.25), rotation=np.eye(3),
                texture=Texture("checker", (_BLUE, _WHITE), frequency=2.0),
                motion=RigidMotion(centre=(0.7, 0.6, -0.45), omega=(0.0, 0.0, 3.0)))
    egg = Body("egg", "ellipsoid", centre=(0.1, -0.6, 0.35), size=(0.3, 0.18, 0.18), rotation=np.eye(3),
               texture=Texture("checker", (_PURPLE, _TEAL), frequency=2.0),
               motion=RigidMotion(centre=(0.1, -0.6, 0.35), omega=(2.5, 0.0, 0.0), velocity=(0.0, 0.9, 0.0)))
    ground = Body("ground", "plane", centre=(0.0, 0.0, -0.7), size=(1.8, 1.8, 1.0), rotation=np.eye(3),
                  texture=Texture("checker", (_GREY_DARK, _GREY_LIGHT), frequency=3.0),
                  motion=StaticMotion())
    return AnalyticScene("multi", [ball, cube, egg, ground], effects=["translation", "rotation", "static"],
                         incompressible=True)


def stretch():
    """A checkered cube stretched 1.8× along x by t = 1, volume-preserving (k = ln 1.8)."""
    k = np.log(1.8)
    cube = Body("cube", "box", centre=(0.0, 0.0, 0.0), size=(0.4, 0.4, 0.4), rotation=np.eye(3),
                texture=Texture("checker", (_GREEN, _WHITE), frequency=2.0),
                motion=LinearFlowMotion(centre=(0.0, 0.0, 0.0), generator=np.diag([k, -k / 2, -k / 2])))
    return AnalyticScene("stretch", [cube], effects=["stretch"], incompressible=True)


def shear():
    """A checkered cube under pure shear in the x–z plane at rate γ = 0.6 per unit time."""
    gamma = 0.6
    generator = np.zeros((3, 3))
    generator[0, 2] = generator[2, 0] = gamma
    cube = Body("cube", "box", centre=(0.0, 0.0, 0.0), size=(0.4, 0.4, 0.4), rotation=np.eye(3),
                texture=Texture("checker", (_PURPLE, _YELLOW), frequency=2.0),
                motion=LinearFlowMotion(centre=(0.0, 0.0, 0.0), generator=generator))
    return AnalyticScene("shear", [cube], effects=["shear"], incompressible=True)


def grow():
    """A checkered sphere growing uniformly to 1.5× its radius by t = 1 (compressible)."""
    k = np.log(1.5)
    ball = Body("ball", "ellipsoid", centre=(0.0, 0.0, 0.0), size=(0.4, 0.4, 0.4), rotation=_tilt((0.4, 0.2, 0.0)),
                texture=Texture("checker", (_BLUE, _YELLOW), frequency=2.0),
                motion=LinearFlowMotion(centre=(0.0, 0.0, 0.0), generator=k * np.eye(3)))
    return AnalyticScene("grow", [ball], effects=["stretch"], incompressible=False)


def pulse():
    """A checkered cube stretched along x by up to 1.6x and back, with period 2/3 (ω = 3π)."""
    k = np.log(1.6)
    cube = Body("cube", "box", centre=(0.0, 0.0, 0.0), size=(0.4, 0.4, 0.4), rotation=np.eye(3),
                texture=Texture("checker", (_RED, _WHITE), frequency=2.0),
                motion=PeriodicFlowMotion(centre=(0.0, 0.0, 0.0), generator=np.diag([k, -k / 2, -k / 2]),
                                          omega=3.0 * np.pi))
    return AnalyticScene("pulse", [cube], effects=["stretch", "oscillation"], incompressible=True)


SCENES = {"spin": spin, "toss": toss, "multi": multi, "stretch": stretch, "shear": shear, "grow": grow,
          "pulse": pulse}
DEFAULT_SCENE = "toss"


def scene_listing(scenes, default):
    """One line per scene: name, effects, compressibility and what moves (its builder's docstring)."""
    lines = []
    for key, build in scenes.items():
        scene = build()
        doc = (inspect.getdoc(build) or "").splitlines()[0]
        tag = " (default)" if key == default else ""
        kind = "incompressible" if scene.incompressible else "compressible"
        lines.append(f"{key + tag:<18} effects: {', '.join(scene.effects):<34} {kind:<15} {doc}")
    return "\n".join(lines)


def load_ground_truth(scene_dir):
    """Rebuild the `AnalyticScene` (bodies, motions, light) from `scene_dir/scene.json`.

    Raises `velogauss.data.errors.DataError` naming the file when it is missing or was not
    written by `velogauss.scenes.writer` (no `scene` description).
    """
    file = Path(scene_dir) / "scene.json"
    try:
        meta = json.loads(file.read_text())
    except OSError as err:
        raise DataError(file, "file",
                        f"cannot read ({err.strerror or err}); only generated scenes have ground truth") from None
    except json.JSONDecodeError as err:
        raise DataError(file, "file", f"not valid JSON ({err})") from None
    if not isinstance(meta, dict) or "scene" not in meta:
        raise DataError(file, "scene", "missing key; not a scene written by velogauss.scenes.writer")
    try:
        return AnalyticScene.from_dict(meta["scene"])
    except ValueError as err:
        raise DataError(file, "scene", str(err)) from None
