"""The scene family: random analytic scenes with exact ground truth, drawn from one documented
distribution, so that defaults can be tuned on some seeds and reported on others.

`draw_parameters(seed)` draws a scene's parameters (no rendering; a JSON-ready dict),
`scene_from_parameters` and `rig_cameras` rebuild the scene and its cameras from them, and
`make_random_scene(seed, out_dir)` renders it with `velogauss.scenes.writer.write_scene`
(`velogauss make-scene --random SEED`). The catalogue's scenes (`catalog.SCENES`,
`velogauss make-scene NAME`) stay the family's named members.

The distribution, each range a constant below with its reason:

- 1–3 bodies (`N_BODIES`), each a box, an ellipsoid or an elliptic cylinder (`SHAPES`, equal
  odds) of half-sizes `HALF_SIZE` per axis (the top end lowered by `HALF_SIZE_SHRINK` per
  extra body), in a uniformly random orientation, with a random texture (one of
  bodies.TEXTURES, two colours at least `MIN_CONTRAST` apart whose mean is
  `BACKGROUND_CONTRAST` from the background's, `TEXTURE_FREQUENCY` cells per unit); an
  optional still checkered ground square (`GROUND_PROBABILITY`, height `GROUND_HEIGHT`),
  always present under a bouncing body.
- each body moves by one of `KINDS` (equal odds; a draw where no body moves is redrawn):
  `flight` (RigidMotion: thrown under gravity `GRAVITY` along −z, apex at `APEX_TIME`,
  tumbling at up to `MAX_TURN_RATE`), `spin` (in place, `SPIN_RATE`), `orbit` (OrbitMotion:
  radius `ORBIT_RADIUS`, rate `ORBIT_RATE`, a spin of its own at `SPIN_RATE` at least
  `ORBIT_SPIN_GAP` away), `pendulum` (PendulumMotion about a horizontal hinge: rod
  `PENDULUM_LENGTH`, amplitude `PENDULUM_AMPLITUDE`, `OSCILLATION_RATE`), `pulse`
  (OscillatingStretchMotion along the body's axes: `PULSE_AMPLITUDE`, `OSCILLATION_RATE`,
  a phase per axis), `flow` (LinearFlowMotion: a volume-preserving stretch along a world axis
  or a pure shear in a world plane at `FLOW_RATE`), `bounce` (BounceMotion on the ground:
  `GRAVITY`, `RESTITUTION`, a spin about the vertical) or `still`.
- a camera rig of `N_CAMERAS` cameras at `CAMERA_DISTANCE` looking at the origin with
  D-NeRF's field of view (`RIGS`): a `ring` (the catalogue's: elevations cycling through
  `RING_ELEVATIONS_DEG`), a `hemisphere` (a Fibonacci spiral, uniform in area between
  `HEMISPHERE_ELEVATIONS_DEG`) or `monocular` (the ring, one train view per frame, cycling);
  a quarter of the cameras (at least one) held out.
- square images of `RESOLUTION` px, `N_FRAMES` frames evenly spaced in t ∈ [0, 1], a white or
  black `BACKGROUND` (recorded in scene.json; the loader composites under it), and the last
  `FUTURE_FRACTION` of the clip as the future: the observed window ends at the frame nearest
  `1 − F`, recorded as scene.json's `max_time`, which the loader uses unless told otherwise.
- every solid body stays inside every camera's image, with a margin `VIEW_MARGIN`, at the
  `CHECK_TIMES`, future included; no two bodies' bounding spheres meet, and none dips below
  the ground; a body that fails is redrawn (`MAX_BODY_TRIES`), then all the bodies
  (`MAX_PLACEMENTS`), then the whole scene.

Declared effects (scene.json's `effects`, like the catalogue's): the VG-BASIS column groups
the bodies' velocities use, `gravity` for `flight` and `bounce`, `oscillation` for `orbit`,
`pendulum` and `pulse`, `static` for a still body or the ground. `incompressible`: every
body's motion keeps its volume (`flow` does; `pulse` in general does not).

`TUNING_SEEDS` and `REPORT_SEEDS` are the two disjoint seed lists for studies: tune defaults
on the first, report on the second.
"""

import numpy as np

from velogauss.data.cameras import Camera, intrinsics_from_fov, look_at
from velogauss.scenes.bodies import TEXTURES, Body, Texture, body_from_dict, half_extent
from velogauss.scenes.scene import AnalyticScene
from velogauss.scenes.trajectories import (BounceMotion, LinearFlowMotion, OrbitMotion, OscillatingStretchMotion,
                                           PendulumMotion, RigidMotion, StaticMotion)
from velogauss.scenes.writer import DNERF_CAMERA_ANGLE_X, spread_heldout, write_scene
from velogauss_core.motion import COLUMN_GROUPS, EFFECTS

# Recorded with every draw; a change to any range below changes it, so a seed names one scene per version.
FAMILY_VERSION = 1
# Seeds to tune defaults on, and disjoint seeds to report them on (never tuned on).
TUNING_SEEDS = tuple(range(0, 24))
REPORT_SEEDS = tuple(range(1000, 1024))

# --- bodies -----------------------------------------------------------------------------------
# Up to three bodies: occlusion and several motions at once, yet each a sizeable part of the image.
N_BODIES = (1, 3)
# The ray-caster's solid primitives (bodies.PRIMITIVES without the plane).
SHAPES = ("box", "ellipsoid", "cylinder")
# Half-sizes per axis: a body spans 10–30 % of the view's width at the ring's distance.
HALF_SIZE = (0.15, 0.4)
# The largest half-size shrinks by this for each body beyond the first: three bodies share the view.
HALF_SIZE_SHRINK = 0.06
# Texture colours: each channel inside this range, off pure black and white.
COLOR_RANGE = (0.05, 0.95)
# Two texture colours at least this far apart (RGB distance), so spins and stretches are visible.
MIN_CONTRAST = 0.35
# The texture's mean grey at least this far from the background's, so the silhouette is visible.
BACKGROUND_CONTRAST = 0.35
# Texture cells per unit of primitive coordinates: 3–8 cells across a body.
TEXTURE_FREQUENCY = (1.5, 4.0)
# Where still, spinning, pulsing and flowing bodies sit at t = 0: inside the view with room to deform.
PLACE_LOW, PLACE_HIGH = (-0.7, -0.7, -0.4), (0.7, 0.7, 0.6)
# About half the scenes have a ground: a still body that occludes, and a floor for bounces.
GROUND_PROBABILITY = 0.4
# The ground's height: below the placed bodies, above the view's bottom edge.
GROUND_HEIGHT = (-0.9, -0.6)
# The ground square's half-side: its far edge stays near the horizon of the lowest cameras.
GROUND_HALF_SIZE = 4.0
# The ground's checker: a dark grey and one GROUND_STEP lighter, neutral under any body colour.
GROUND_GREY = (0.3, 0.5)
GROUND_STEP = 0.35
GROUND_FREQUENCY = (2.0, 4.0)

# --- motions ----------------------------------------------------------------------------------
KINDS = ("flight", "spin", "orbit", "pendulum", "pulse", "flow", "bounce", "still")
# 1.5 turns per unit time: at most 36° between frames of the sparsest clip, an unambiguous turn.
MAX_TURN_RATE = 3.0 * np.pi
# A spin in place (or an orbiting body's own) from slow to MAX_TURN_RATE.
SPIN_RATE = (1.0, MAX_TURN_RATE)
# Gravity from weak to 1.5× the catalogue's toss (8), capped by MAX_DROP.
GRAVITY = (3.0, 12.0)
# The apex inside the clip, so the flight both rises and falls.
APEX_TIME = (0.3, 0.7)
# The largest rise or fall of a flight over the clip: about the view's half-height (less over a ground).
MAX_DROP = 1.2
# The highest point of a flight.
APEX_HEIGHT = (0.2, 0.7)
# Horizontal launch speed: a drift of at most 0.8 units over the clip.
DRIFT_SPEED = (0.0, 0.8)
# Orbit: radius about the pivot and rate, from a quarter turn to one turn over the clip.
ORBIT_RADIUS = (0.3, 0.7)
ORBIT_RATE = (0.5 * np.pi, 2.0 * np.pi)
# The pivot lies within this share of the placement box, so the orbit fits around it.
PIVOT_SPREAD = 0.5
# An orbiting body's own spin rate differs from the orbit's by at least this (rad per unit time).
ORBIT_SPIN_GAP = 1.0
# Pendulum: hinge-to-centre length and the swing's amplitude (rad, about 17°–57°).
PENDULUM_LENGTH = (0.4, 0.9)
# The hinge's height, and its horizontal spread as a share of the placement box: the bob swings in view.
HINGE_HEIGHT = (0.4, 0.9)
HINGE_SPREAD = 0.6
PENDULUM_AMPLITUDE = (0.3, 1.0)
# Swings and pulses: periods of 0.5 to 2, from half an oscillation to two over the clip.
OSCILLATION_RATE = (np.pi, 4.0 * np.pi)
# Oscillating stretch: log-stretch amplitude per axis (up to 2× between extremes).
PULSE_AMPLITUDE = (0.1, 0.35)
# Linear flow: stretch or shear rate (the catalogue's are ln 1.8 ≈ 0.59 and 0.6).
FLOW_RATE = (0.3, 0.7)
# Bounce: drop height above the floor, launch speed up, restitution, horizontal speed, spin rate.
BOUNCE_HEIGHT = (0.3, 1.0)
BOUNCE_UP_SPEED = (-0.5, 1.5)
RESTITUTION = (0.4, 0.85)
BOUNCE_DRIFT_SPEED = (0.0, 0.6)
BOUNCE_SPIN_RATE = 2.0 * np.pi
# The first bounce comes before this time, so every bouncing clip shows one.
LAST_FIRST_BOUNCE = 0.85

# --- cameras, images, time --------------------------------------------------------------------
RIGS = ("ring", "hemisphere", "monocular")
# From the sparsest rig that still triangulates to D-NeRF-like density.
N_CAMERAS = (4, 24)
# The catalogue's ring: the distance, and the elevations cycled with ± RING_JITTER_DEG.
CAMERA_DISTANCE = 4.0
RING_ELEVATIONS_DEG = (20.0, 35.0, 50.0)
RING_JITTER_DEG = 3.0
# Hemisphere: from low views to nearly overhead (the look-at up vector is z).
HEMISPHERE_ELEVATIONS_DEG = (10.0, 75.0)
# The golden angle: successive spiral cameras fill azimuth evenly.
GOLDEN_ANGLE_DEG = 180.0 * (3.0 - np.sqrt(5.0))
# Square images, multiples of 16 (even after half_res), from the quick to the catalogue's 128 and above.
RESOLUTION = (64, 160)
RESOLUTION_STEP = 16
# Frames over t ∈ [0, 1]: from sparse to dense sampling of the fastest motions.
N_FRAMES = (16, 60)
# The future: the last 20–30 % of the clip.
FUTURE_FRACTION = (0.2, 0.3)
BACKGROUND = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0)}
# Light: elevation of its direction (degrees) and the ambient share, which keeps unlit faces textured.
LIGHT_ELEVATION_DEG = (30.0, 80.0)
AMBIENT = (0.35, 0.6)

# --- checks -----------------------------------------------------------------------------------
# Times at which bodies must be in view and apart: the fastest body (a long, wide, quick swing) moves
# under 0.2 units between samples.
CHECK_TIMES = np.linspace(0.0, 1.0, 61)
# Fraction of the image side kept clear around every body's projected box.
VIEW_MARGIN = 0.04
# Draws of one body before all bodies are placed anew, placements before the whole scene is redrawn:
# retrying the bodies first keeps the drawn counts, kinds and shapes from leaning to easy scenes.
MAX_BODY_TRIES = 30
MAX_PLACEMENTS = 20
MAX_SCENE_TRIES = 1000
# The coarse pass of the checks reads every 10th check time.
_COARSE = 10
# A motion keeps volume when det A stays within this of 1 (rounding of exact rotations and trace-free flows).
_VOLUME_TOL = 1e-9
# Touching (a bounce on the ground) is allowed to rounding.
_CONTACT_TOL = 1e-9
# Which effects a kind declares besides its velocity's column groups.
_KIND_EFFECTS = {"flight": ("gravity",), "bounce": ("gravity",), "orbit": ("oscillation",),
                 "pendulum": ("oscillation",), "pulse": ("oscillation",), "still": ("static",)}


def draw_parameters(seed):
    """The parameters of the family's scene `seed` (an int ≥ 0): a JSON-ready dict, the same for
    the same seed and FAMILY_VERSION. Raises ValueError naming `seed` when it is not an int ≥ 0."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    for _ in range(MAX_SCENE_TRIES):
        params = _draw_scene(rng, int(seed))
        if params is not None:
            return params
    raise RuntimeError(f"seed {seed}: no scene fits after {MAX_SCENE_TRIES} draws")  # never seen


def scene_from_parameters(params):
    """The `AnalyticScene` of `draw_parameters`' dict: its bodies (and ground), effects, light."""
    bodies = [body_from_dict(b) for b in params["bodies"]]
    ground = [body_from_dict(params["ground"])] if params["ground"] else []
    effects = _effects(bodies, params["kinds"], bool(ground))
    incompressible = all(abs(np.linalg.det(b.motion.affine(t)[0]) - 1.0) < _VOLUME_TOL for b in bodies
                         for t in CHECK_TIMES)
    return AnalyticScene(params["name"], bodies + ground, effects, incompressible, light=params["light"],
                         ambient=params["ambient"])


def rig_cameras(params, resolution=None):
    """The rig's cameras, square images of `resolution` px (default: the drawn one)."""
    size = int(params["resolution"] if resolution is None else resolution)
    K = intrinsics_from_fov(params["camera_angle_x"], size, size)
    cameras = []
    for az, el in zip(np.radians(params["azimuths_deg"]), np.radians(params["elevations_deg"])):
        eye = params["camera_distance"] * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        cameras.append(Camera(look_at(eye, np.zeros(3)), K, size, size))
    return cameras


def frame_times(n_frames, future_fraction):
    """`(times (n,), max_time)`: n evenly spaced times in [0, 1] and the observed window's end, the
    frame time nearest `1 − future_fraction` (at least one frame on each side)."""
    times = np.linspace(0.0, 1.0, n_frames)
    last = min(max(int(round((1.0 - future_fraction) * (n_frames - 1))), 1), n_frames - 2)
    return times, float(times[last])


def make_random_scene(seed, out_dir, *, resolution=None, n_frames=None, supersample=2, n_points=2000):
    """Render the family's scene `seed` into `out_dir` (writer.py's layout) and return its Path.

    `resolution` (px, square) and `n_frames` (≥ 3) override the drawn ones (the geometry, and so
    the in-view check, does not depend on them; the window's end is recomputed from the drawn
    future fraction); both are recorded in scene.json's `family.overrides`. Raises ValueError
    naming the argument for a bad option.
    """
    for arg, value, low in (("resolution", resolution, 2), ("n_frames", n_frames, 3), ("supersample", supersample, 1),
                            ("n_points", n_points, 0)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low):
            raise ValueError(f"{arg}: expected an integer >= {low}, got {value!r}")
    params = draw_parameters(seed)
    size = int(params["resolution"] if resolution is None else resolution)
    n = int(params["n_frames"] if n_frames is None else n_frames)
    times, max_time = frame_times(n, params["future_fraction"])
    scene = scene_from_parameters(params)
    cameras = rig_cameras(params, size)
    heldout = spread_heldout(len(cameras), max(1, len(cameras) // 4))
    layout = "monocular" if params["rig"] == "monocular" else "multiview"
    rng = np.random.default_rng([int(seed), 1])  # the point cloud's own stream: overrides leave the draw alone
    generator = {"resolution": [size, size], "n_views": len(cameras), "n_heldout": len(heldout), "n_times": n,
                 "seed": int(seed), "supersample": int(supersample), "n_points": int(n_points), "layout": layout,
                 "future_after": max_time, "camera_distance": params["camera_distance"],
                 "camera_angle_x": params["camera_angle_x"], "azimuths_deg": params["azimuths_deg"],
                 "elevations_deg": params["elevations_deg"]}
    overrides = {k: v for k, v in (("resolution", resolution), ("n_frames", n_frames)) if v is not None}
    family = {"seed": int(seed), "version": FAMILY_VERSION, "overrides": {k: int(v) for k, v in overrides.items()},
              "parameters": params}
    return write_scene(scene, cameras, heldout, out_dir, times, rng, generator, supersample=supersample,
                       n_points=n_points, layout=layout, future_after=max_time,
                       camera_angle_x=params["camera_angle_x"], background=BACKGROUND[params["background"]],
                       extra={"family": family})


# --- the draw ---------------------------------------------------------------------------------

def _draw_scene(rng, seed):
    """One attempt: the parameters, or None when a body found no place."""
    resolution = int(rng.integers(RESOLUTION[0] // RESOLUTION_STEP, RESOLUTION[1] // RESOLUTION_STEP + 1))
    params = {"name": f"random-{seed}", "seed": seed, "version": FAMILY_VERSION,
              "resolution": resolution * RESOLUTION_STEP,
              "n_frames": int(rng.integers(N_FRAMES[0], N_FRAMES[1] + 1)),
              "future_fraction": float(rng.uniform(*FUTURE_FRACTION)),
              "background": str(rng.choice(sorted(BACKGROUND))),
              **_draw_rig(rng), **_draw_light(rng)}
    params["max_time"] = frame_times(params["n_frames"], params["future_fraction"])[1]
    n_bodies = int(rng.integers(N_BODIES[0], N_BODIES[1] + 1))
    kinds = [str(k) for k in rng.choice(KINDS, size=n_bodies)]
    while all(k == "still" for k in kinds):  # a scene that never moves has no future to predict
        kinds = [str(k) for k in rng.choice(KINDS, size=n_bodies)]
    ground_z = None
    if "bounce" in kinds or rng.uniform() < GROUND_PROBABILITY:
        ground_z = float(rng.uniform(*GROUND_HEIGHT))
    shapes = [str(s) for s in rng.choice(SHAPES, size=n_bodies)]
    rig = _rig_arrays(rig_cameras(params))
    for _ in range(MAX_PLACEMENTS):
        bodies = _place(rng, kinds, shapes, rig, ground_z, params["background"])
        if bodies is not None:
            break
    else:
        return None
    params["kinds"] = kinds
    params["bodies"] = [{"kind": kind, **body.to_dict()} for kind, body in zip(kinds, bodies)]
    params["ground"] = None if ground_z is None else _ground(rng, ground_z).to_dict()
    return params


def _place(rng, kinds, shapes, rig, ground_z, background):
    """Bodies of the given kinds and shapes, each drawn until it fits beside the ones before; None
    when one does not fit in MAX_BODY_TRIES."""
    bodies, tracks = [], []
    for index, (kind, shape) in enumerate(zip(kinds, shapes)):
        for _ in range(MAX_BODY_TRIES):
            body = _draw_body(rng, index, len(kinds), kind, shape, ground_z, background)
            path = None if body is None else _fits(body, kind, tracks, rig, ground_z)
            if path is not None:
                bodies.append(body)
                tracks.append(path)
                break
        else:
            return None
    return bodies


def _draw_rig(rng):
    rig = str(rng.choice(RIGS))
    n = int(rng.integers(N_CAMERAS[0], N_CAMERAS[1] + 1))
    start = rng.uniform(0.0, 360.0)
    if rig == "hemisphere":
        low, high = np.sin(np.radians(HEMISPHERE_ELEVATIONS_DEG))
        elevations = np.degrees(np.arcsin(low + (high - low) * (np.arange(n) + 0.5) / n))
        azimuths = (start + GOLDEN_ANGLE_DEG * np.arange(n)) % 360.0
    else:
        azimuths = (start + 360.0 * np.arange(n) / n) % 360.0
        elevations = (np.array(RING_ELEVATIONS_DEG)[np.arange(n) % len(RING_ELEVATIONS_DEG)]
                      + rng.uniform(-RING_JITTER_DEG, RING_JITTER_DEG, size=n))
    return {"rig": rig, "n_cameras": n, "azimuths_deg": azimuths.tolist(), "elevations_deg": elevations.tolist(),
            "camera_distance": CAMERA_DISTANCE, "camera_angle_x": DNERF_CAMERA_ANGLE_X}


def _draw_light(rng):
    az, el = rng.uniform(0.0, 2.0 * np.pi), np.radians(rng.uniform(*LIGHT_ELEVATION_DEG))
    return {"light": [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)],
            "ambient": float(rng.uniform(*AMBIENT))}


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _rotation(rng):
    """A uniformly random rotation matrix (a normalised Gaussian quaternion)."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _axis_rotation(axis, angle):
    N = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * N + (1.0 - np.cos(angle)) * N @ N


def _draw_texture(rng, background):
    while True:
        colors = rng.uniform(*COLOR_RANGE, size=(2, 3))
        if (np.linalg.norm(colors[0] - colors[1]) >= MIN_CONTRAST
                and abs(colors.mean() - np.mean(BACKGROUND[background])) >= BACKGROUND_CONTRAST):
            break
    return Texture(str(rng.choice(TEXTURES)), colors, axis=int(rng.integers(3)),
                   frequency=float(rng.uniform(*TEXTURE_FREQUENCY)))


def _ground(rng, height):
    grey = rng.uniform(*GROUND_GREY)
    texture = Texture("checker", (3 * (grey,), 3 * (grey + GROUND_STEP,)),
                      frequency=float(rng.uniform(*GROUND_FREQUENCY)))
    return Body("ground", "plane", (0.0, 0.0, height), (GROUND_HALF_SIZE, GROUND_HALF_SIZE, 1.0), np.eye(3),
                texture, StaticMotion())


def _draw_body(rng, index, n_bodies, kind, shape, ground_z, background):
    """A body of `kind` and `shape`, or None when its drawn motion misses its own condition (a bounce's timing)."""
    size = rng.uniform(HALF_SIZE[0], HALF_SIZE[1] - HALF_SIZE_SHRINK * (n_bodies - 1), size=3)
    rotation = _rotation(rng)
    texture = _draw_texture(rng, background)
    place = rng.uniform(PLACE_LOW, PLACE_HIGH)
    if kind == "still":
        centre, motion = place, StaticMotion()
    elif kind == "spin":
        centre, motion = place, RigidMotion(place, omega=rng.uniform(*SPIN_RATE) * _unit(rng))
    elif kind == "flight":
        apex_time, apex = rng.uniform(*APEX_TIME), rng.uniform(*APEX_HEIGHT)
        drop = MAX_DROP
        if ground_z is not None:  # the tumbling body's bounding sphere stays above the ground
            drop = min(drop, apex - ground_z - np.sqrt(3.0) * size.max())
        g_max = min(GRAVITY[1], 2.0 * drop / max(apex_time, 1.0 - apex_time) ** 2)
        if g_max < GRAVITY[0]:
            return None
        g = rng.uniform(GRAVITY[0], g_max)
        heading = rng.uniform(0.0, 2.0 * np.pi)
        drift = rng.uniform(*DRIFT_SPEED) * np.array([np.cos(heading), np.sin(heading), 0.0])
        centre = np.array([place[0], place[1], apex - 0.5 * g * apex_time ** 2])
        motion = RigidMotion(centre, omega=rng.uniform(0.0, MAX_TURN_RATE) * _unit(rng),
                             velocity=drift + [0.0, 0.0, g * apex_time], gravity=(0.0, 0.0, -g))
    elif kind == "orbit":
        axis = _unit(rng)
        arm = _unit(rng)
        arm -= (arm @ axis) * axis
        pivot = PIVOT_SPREAD * place
        centre = pivot + rng.uniform(*ORBIT_RADIUS) * arm / np.linalg.norm(arm)
        rate = rng.uniform(*ORBIT_RATE)
        spin = rng.uniform(*SPIN_RATE)
        while abs(spin - rate) < ORBIT_SPIN_GAP:
            spin = rng.uniform(*SPIN_RATE)
        motion = OrbitMotion(pivot, centre, rate * axis, spin * _unit(rng))
    elif kind == "pendulum":
        heading = rng.uniform(0.0, 2.0 * np.pi)
        axis = np.array([np.cos(heading), np.sin(heading), 0.0])
        hinge = np.array([HINGE_SPREAD * place[0], HINGE_SPREAD * place[1], rng.uniform(*HINGE_HEIGHT)])
        amplitude, omega = rng.uniform(*PENDULUM_AMPLITUDE), rng.uniform(*OSCILLATION_RATE)
        phase = rng.uniform(0.0, 2.0 * np.pi)
        swing = _axis_rotation(axis, amplitude * np.cos(phase))
        centre = hinge + swing @ [0.0, 0.0, -rng.uniform(*PENDULUM_LENGTH)]
        rotation = swing @ rotation
        motion = PendulumMotion(hinge, axis, amplitude, omega, phase)
    elif kind == "pulse":
        amplitude = rng.uniform(*PULSE_AMPLITUDE, size=3) * rng.choice([-1.0, 1.0], size=3)
        centre = place
        motion = OscillatingStretchMotion(place, rotation, amplitude, rng.uniform(*OSCILLATION_RATE),
                                          rng.uniform(0.0, 2.0 * np.pi, size=3))
    elif kind == "flow":
        rate = rng.uniform(*FLOW_RATE) * rng.choice([-1.0, 1.0])
        generator = np.zeros((3, 3))
        i, j = rng.permutation(3)[:2]
        if rng.uniform() < 0.5:  # a volume-preserving stretch along world axis i
            generator[i, i], generator[j, j], generator[3 - i - j, 3 - i - j] = rate, -rate / 2, -rate / 2
        else:  # a pure shear in the world plane (i, j): symmetric and trace-free
            generator[i, j] = generator[j, i] = rate
        centre, motion = place, LinearFlowMotion(place, generator)
    elif kind == "bounce":
        still = Body("probe", shape, (0.0, 0.0, 0.0), size, rotation, texture, StaticMotion())
        floor = ground_z + still.aabb(0.0)[1, 2]  # the centre's height when the body touches the ground
        heading = rng.uniform(0.0, 2.0 * np.pi)
        drift = rng.uniform(*BOUNCE_DRIFT_SPEED) * np.array([np.cos(heading), np.sin(heading), 0.0])
        centre = np.array([place[0], place[1], floor + rng.uniform(*BOUNCE_HEIGHT)])
        motion = BounceMotion(centre, drift + [0.0, 0.0, rng.uniform(*BOUNCE_UP_SPEED)], rng.uniform(*GRAVITY), floor,
                              rng.uniform(*RESTITUTION), rng.uniform(-BOUNCE_SPIN_RATE, BOUNCE_SPIN_RATE))
        if motion.first_impact()[0] > LAST_FIRST_BOUNCE:
            return None
    else:
        raise ValueError(f"kind: unknown motion kind {kind!r}; choose one of {KINDS}")
    return Body(f"body{index}", shape, centre, size, rotation, texture, motion)


# --- the checks -------------------------------------------------------------------------------

# The unit cube's corners, which bound every solid primitive.
_CORNERS = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])


def track(body, times=CHECK_TIMES):
    """The body at `times (T,)`: the corners `(T, 8, 3)` of a parallelepiped holding it, its lowest
    height `(T,)`, its centre `(T, 3)` and a bounding sphere's radius `(T,)` about it."""
    poses = [body.to_world(t) for t in times]
    L, centres = np.array([pose[0] for pose in poses]), np.array([pose[1] for pose in poses])
    corners = np.einsum("tij,kj->tki", L, _CORNERS) + centres[:, None]
    lowest = centres[:, 2] - half_extent(body.primitive, L)[:, 2]
    # The ellipsoid's exact radius; the cube's corners bound a box exactly and a cylinder loosely.
    if body.primitive == "ellipsoid":
        radii = np.linalg.norm(L, 2, axis=(1, 2))
    else:
        radii = np.linalg.norm(corners - centres[:, None], axis=2).max(axis=1)
    return corners, lowest, centres, radii


def in_view(corners, cameras, margin=VIEW_MARGIN):
    """Whether the points `corners (..., 3)` lie in front of every camera and inside its image, `margin`
    of its side clear."""
    return _visible(corners, _rig_arrays(cameras), margin)


def _rig_arrays(cameras):
    """The cameras' rotations `(C, 3, 3)`, translations `(C, 3)`, focal lengths and principal points
    `(C, 2)` in units of the image's sides."""
    size = np.array([[c.width, c.height] for c in cameras], dtype=np.float64)
    return (np.array([c.viewmat[:3, :3] for c in cameras]), np.array([c.viewmat[:3, 3] for c in cameras]),
            np.array([[c.K[0, 0], c.K[1, 1]] for c in cameras]) / size,
            np.array([[c.K[0, 2], c.K[1, 2]] for c in cameras]) / size)


def _visible(corners, rig, margin=VIEW_MARGIN):
    R, T, focal, centre = rig
    cam = corners.reshape(-1, 3) @ R.transpose(0, 2, 1) + T[:, None]  # (C, N, 3)
    if np.any(cam[..., 2] <= 0):
        return False
    uv = focal[:, None] * cam[..., :2] / cam[..., 2:] + centre[:, None]
    return bool(np.all((uv >= margin) & (uv <= 1.0 - margin)))


def apart(first, second):
    """Whether two `track`s' bounding spheres stay apart at every time."""
    return bool(np.all(np.linalg.norm(first[2] - second[2], axis=1) >= first[3] + second[3]))


def _fits(body, kind, placed, rig, ground_z):
    """The body's `track` when it stays in view, above the ground (a bounce over it) and apart from the
    `placed` tracks at CHECK_TIMES, else None; a pass at every `_COARSE`-th time first rejects most
    misfits cheaply."""
    for step in (_COARSE, 1):
        path = track(body, CHECK_TIMES[::step])
        corners, lowest = path[0], path[1]
        if ground_z is not None and np.any(lowest < ground_z - _CONTACT_TOL):
            return None
        if kind == "bounce" and np.any(np.abs(corners[..., :2]) > GROUND_HALF_SIZE):
            return None
        if not all(apart(path, [a[::step] for a in other]) for other in placed) or not _visible(corners, rig):
            return None
    return path


def _effects(bodies, kinds, ground):
    effects = {"static"} if ground else set()
    for body, kind in zip(bodies, kinds):
        effects.update(_KIND_EFFECTS.get(kind, ()))
        if kind == "still":
            continue
        w = np.abs([body.motion.basis_coefficients(t) for t in CHECK_TIMES]).max(axis=0)
        effects.update(group for group, columns in COLUMN_GROUPS.items() if w[list(columns)].max() > 1e-9)
    return [e for e in EFFECTS if e in effects]
