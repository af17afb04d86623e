"""Render a synthetic scene to disk in the D-NeRF, nerfstudio or Panoptic layout that `load_scene` reads.

`make_scene` renders a named catalogue scene seen by the camera ring below; `write_scene`
renders any `AnalyticScene` seen by given cameras (the family's random scenes, family.py).

Written files (in `out_dir`), `format="dnerf"` (the default):

- `transforms_train.json`: the train views at every time in [0, 1] (the loader's
  `max_time` cuts the future off); with `layout="monocular"` one train view per time,
  cycling through the train views (as in D-NeRF).
- `transforms_val.json`: the held-out views at every time.
- `transforms_test.json`: every view at the times `t > future_after` (the future).
- `train/`, `val/`, `test/`: RGBA PNGs, transparent where no body is hit (the static
  ground of `multi` is opaque), anti-aliased with `supersample²` rays per pixel.
- with `format="nerfstudio"` instead of the three files and folders: `transforms.json` with
  `camera_model` "OPENCV" (no distortion), `ply_file_path`, one frame per rendered (view, time)
  with its own `fl_x, fl_y, cx, cy, w, h`, `transform_matrix` (camera-to-world, OpenGL axes),
  `time` and `file_path` `images/r_VV_TTT.png` (RGBA PNGs as above), and the lists
  `train_filenames`, `val_filenames`, `test_filenames` holding the frames of the D-NeRF files of
  the same name in the same order, so both layouts load to the same splits.
- with `format="panoptic"` instead (Dynamic3DGaussians' layout, velogauss/data/panoptic.py):
  `train_meta.json` (the train views) and `test_meta.json` (the held-out views), each with `w`, `h`
  and per time index `t` and view `c` `k[t][c]`, `w2c[t][c]` (OpenCV world-to-camera), `fn[t][c]`
  = `"<view>/<t:06d>.jpg"` and `cam_id[t][c]` = the view; `ims/<view>/<t:06d>.jpg` the straight
  (not premultiplied) RGB as JPEG at quality 95 without chroma subsampling; `seg/<view>/<t:06d>.png`
  the alpha as an 8-bit grey PNG (the loader's mask); `init_pt_cld.npz` (`data` (N, 7): the points
  below, their colours and seg 1) instead of `points3d.ply`. With `layout="monocular"` each time
  step lists its one train view. There is no future file: the loader's test role is every frame.
- `points3d.ply`: points on the bodies' surfaces at t = 0 with their t = 0 colours.
- `scene.json`: `name`, `effects`, `incompressible`, `bounds` (box of all bodies over
  t in [0, 1]), `max_time` (the observed window's end, `future_after`, which the loader
  takes when none is given), `background` (only where the scene has its own, which the
  loader takes likewise), `motion` (per body, `x(t) = A(t) x0 + b(t)` with its
  parameters), the full `scene` description (`load_ground_truth` rebuilds it) and the
  `generator` settings.

Cameras sit on a ring around the scene's `look_at` point at `camera_distance`, azimuths
evenly spaced from a seeded random start, elevations cycling through 20°, 35°, 50°
(± 3° seeded jitter); `n_heldout` of them, evenly spread, are held out.
"""

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from velogauss.data.cameras import Camera, intrinsics_from_fov, look_at
from velogauss.data.ply import write_ply
from velogauss.scenes.catalog import SCENES

SCENE_FORMATS = ("dnerf", "nerfstudio", "panoptic")
PANOPTIC_JPEG_QUALITY = 95
# Horizontal field of view of the D-NeRF synthetic scenes (radians): at 4 units it spans
# about ±1.44 units, which frames objects of about one unit with room to move.
DNERF_CAMERA_ANGLE_X = 0.6911112070083618
_ELEVATIONS_DEG = (20.0, 35.0, 50.0)
_ELEVATION_JITTER_DEG = 3.0
_MOTION_MODEL = ("x(t) = A(t) x0 + b(t) for the material point at x0 at t = 0; "
                 "v(x, t) = dA/dt A^-1 (x - b) + db/dt; "
                 "rigid: A = exp(t [omega]x), b = c(t) - A centre, c(t) = centre + velocity t + gravity t^2 / 2; "
                 "linear_flow: A = expm(t generator), b = centre - A centre; "
                 "periodic_flow: A = expm(sin(omega t) generator), b = centre - A centre; static: A = I, b = 0; "
                 "orbit, pendulum, oscillating_stretch, bounce: see velogauss/scenes/trajectories.py")


def make_scene(name, out_dir, resolution=128, n_views=8, n_times=21, seed=0, *, n_heldout=2, supersample=2,
               n_points=2000, layout="multiview", future_after=0.75, camera_distance=4.0,
               camera_angle_x=DNERF_CAMERA_ANGLE_X, format="dnerf"):
    """Render scene `name` (a key of `catalog.SCENES`) into `out_dir` and return its Path.

    `resolution`: int (square) or `(width, height)` in pixels. `n_views` cameras, of which
    `n_heldout` are held out (`1 ≤ n_heldout < n_views`). `n_times ≥ 2` times `k / (n_times − 1)`.
    `seed` fixes the camera ring's azimuth offset and elevation jitter and the point-cloud
    samples (the scene itself is deterministic). `supersample`: rays per pixel side.
    `n_points`: size of `points3d.ply`. `layout`: "multiview" or "monocular".
    `future_after`: times after it form `transforms_test.json`. `format`: "dnerf", "nerfstudio" or
    "panoptic", the layout written (module docstring). Existing files are
    overwritten. Defaults (128×128, 8 views, 21 times) render in a few seconds. At 64×64 the
    motion of the slow scenes inside the window is 1–3 px, and their learned velocity error
    was twice that at 128×128 for the same training time (benchmarks/FIDELITY.md).
    Raises ValueError naming the argument for a bad option.
    """
    if name not in SCENES:
        raise ValueError(f"name: unknown scene {name!r}; choose one of {sorted(SCENES)}")
    width, height = _resolution(resolution)
    for arg, value, low in (("n_views", n_views, 2), ("n_times", n_times, 2), ("supersample", supersample, 1),
                            ("n_points", n_points, 0), ("n_heldout", n_heldout, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{arg}: expected an integer >= {low}, got {value!r}")
    if n_heldout >= n_views:
        raise ValueError(f"n_heldout: must be < n_views={n_views} so that train views remain, got {n_heldout}")
    if format not in SCENE_FORMATS:
        raise ValueError(f"format: expected one of {', '.join(SCENE_FORMATS)}, got {format!r}")
    if layout not in ("multiview", "monocular"):
        raise ValueError(f"layout: expected 'multiview' or 'monocular', got {layout!r}")
    times = np.linspace(0.0, 1.0, n_times)
    if not 0.0 <= future_after < 1.0 or not np.any(times > future_after):
        raise ValueError(
            f"future_after: expected a value in [0, 1) with at least one time after it, got {future_after!r}")
    if not camera_distance > 0:
        raise ValueError(f"camera_distance: expected > 0, got {camera_distance!r}")

    scene = SCENES[name]()
    rng = np.random.default_rng(seed)
    cameras, ring = _camera_ring(scene.look_at, n_views, camera_distance, camera_angle_x, width, height, rng)
    generator = {"resolution": [width, height], "n_views": int(n_views), "n_heldout": int(n_heldout),
                 "n_times": int(n_times), "seed": None if seed is None else int(seed),
                 "supersample": int(supersample), "n_points": int(n_points), "layout": layout,
                 "future_after": float(future_after), "camera_distance": float(camera_distance),
                 "camera_angle_x": float(camera_angle_x), "azimuths_deg": ring[0], "elevations_deg": ring[1],
                 **({} if format == "dnerf" else {"format": format})}
    return write_scene(scene, cameras, spread_heldout(n_views, n_heldout), out_dir, times, rng, generator,
                       supersample=supersample, n_points=n_points, layout=layout, future_after=future_after,
                       camera_angle_x=camera_angle_x, format=format)


def spread_heldout(n_views, n_heldout):
    """The `n_heldout` held-out camera indices of `n_views`, evenly spread."""
    return sorted({int(round((j + 0.5) * n_views / n_heldout)) % n_views for j in range(n_heldout)})


def write_scene(scene, cameras, heldout, out_dir, times, rng, generator, *, supersample, n_points, layout,
                future_after, camera_angle_x, background=None, extra=None, format="dnerf"):
    """Render `scene` (an `AnalyticScene`) seen by `cameras` into `out_dir` (module docstring) and return its Path.

    `heldout`: the held-out camera indices; `times (n,)` in [0, 1]; `rng` draws the point cloud;
    `generator`: the settings recorded in scene.json (the train and held-out views are added);
    `future_after`: the observed window's end, recorded as `max_time`; `background`: an RGB
    triple recorded as the scene's own, or None; `extra`: more top-level scene.json entries;
    `format`: "dnerf", "nerfstudio" or "panoptic", the layout written. The options are checked by the callers.
    """
    train_views = [k for k in range(len(cameras)) if k not in heldout]
    n_times = len(times)
    if layout == "monocular":
        train_pairs = [(train_views[i % len(train_views)], i) for i in range(n_times)]
    else:
        train_pairs = [(k, i) for k in train_views for i in range(n_times)]
    splits = {
        "train": train_pairs,
        "val": [(k, i) for k in heldout for i in range(n_times)],
        "test": [(k, i) for k in range(len(cameras)) for i in range(n_times) if times[i] > future_after],
    }

    out = Path(out_dir)
    renders = {}
    for view in range(len(cameras)):  # one camera's frames together: its rays are computed once
        needed = sorted({i for pairs in splits.values() for v, i in pairs if v == view})
        images = scene.render_sequence(cameras[view], [float(times[i]) for i in needed], supersample)
        for i, rgba in zip(needed, images):
            renders[(view, i)] = np.round(np.clip(rgba, 0.0, 1.0) * 255.0).astype(np.uint8)
    if format == "nerfstudio":
        _write_nerfstudio(out, cameras, times, splits, renders)
    elif format == "panoptic":
        _write_panoptic(out, cameras, splits, renders)
    else:
        for split, pairs in splits.items():
            (out / split).mkdir(parents=True, exist_ok=True)
            frames = []
            for view, i in pairs:
                stem = f"r_{view:02d}_{i:03d}"
                iio.imwrite(out / split / f"{stem}.png", renders[(view, i)])
                frames.append({"file_path": f"./{split}/{stem}", "time": float(times[i]), "view": view,
                               "transform_matrix": cameras[view].c2w_opengl.tolist()})
            document = {"camera_angle_x": camera_angle_x, "frames": frames}
            (out / f"transforms_{split}.json").write_text(json.dumps(document, indent=1))

    points, colors, normals = scene.sample_surface(n_points, rng)
    if format == "panoptic":
        seg = np.ones((len(points), 1))
        np.savez_compressed(out / "init_pt_cld.npz", data=np.concatenate([points, colors, seg], axis=1))
    else:
        write_ply(out / "points3d.ply", points, colors, normals)
    metadata = {
        "format": "velogauss-scene/1",
        "name": scene.name,
        "effects": scene.effects,
        "incompressible": scene.incompressible,
        "bounds": scene.bounds().tolist(),
        "time_range": [0.0, 1.0],
        "max_time": float(future_after),
        **({} if background is None else {"background": [float(v) for v in background]}),
        "motion": {"model": _MOTION_MODEL,
                   "bodies": [{"name": b.name, **b.motion.to_dict()} for b in scene.bodies]},
        "scene": scene.to_dict(),
        "generator": {**generator, "train_views": train_views, "heldout_views": heldout},
        **(extra or {}),
    }
    (out / "scene.json").write_text(json.dumps(metadata, indent=1))
    return out


def _write_nerfstudio(out, cameras, times, splits, renders):
    """`transforms.json` and `images/` (module docstring): each rendered (view, time) once, in view
    then time order, with its own intrinsics; the split lists keep the D-NeRF files' orders."""
    (out / "images").mkdir(parents=True, exist_ok=True)
    frames = []
    for view, i in sorted(renders):
        camera = cameras[view]
        name = f"images/r_{view:02d}_{i:03d}.png"
        iio.imwrite(out / name, renders[(view, i)])
        frames.append({"file_path": name, "time": float(times[i]), "view": view,
                       "fl_x": float(camera.K[0, 0]), "fl_y": float(camera.K[1, 1]),
                       "cx": float(camera.K[0, 2]), "cy": float(camera.K[1, 2]),
                       "w": int(camera.width), "h": int(camera.height),
                       "transform_matrix": camera.c2w_opengl.tolist()})
    document = {"camera_model": "OPENCV", "ply_file_path": "points3d.ply", "frames": frames,
                **{f"{split}_filenames": [f"images/r_{view:02d}_{i:03d}.png" for view, i in pairs]
                   for split, pairs in splits.items()}}
    (out / "transforms.json").write_text(json.dumps(document, indent=1))


def _write_panoptic(out, cameras, splits, renders):
    """`train_meta.json` (the train views), `test_meta.json` (the held-out views), `ims/` and `seg/`
    (module docstring): per time index, its views in split order."""
    for name, split in (("train_meta.json", "train"), ("test_meta.json", "val")):
        steps = sorted({i for _, i in splits[split]})
        meta = {"w": int(cameras[0].width), "h": int(cameras[0].height), "k": [], "w2c": [], "fn": [], "cam_id": []}
        for i in steps:
            views = [view for view, j in splits[split] if j == i]
            meta["k"].append([cameras[v].K.tolist() for v in views])
            meta["w2c"].append([cameras[v].viewmat.tolist() for v in views])
            meta["fn"].append([f"{v}/{i:06d}.jpg" for v in views])
            meta["cam_id"].append(views)
            for v in views:
                for folder in ("ims", "seg"):
                    (out / folder / str(v)).mkdir(parents=True, exist_ok=True)
                rgba = renders[(v, i)]
                iio.imwrite(out / "ims" / str(v) / f"{i:06d}.jpg", rgba[..., :3], plugin="pillow",
                            extension=".jpg", quality=PANOPTIC_JPEG_QUALITY, subsampling=0)
                iio.imwrite(out / "seg" / str(v) / f"{i:06d}.png", rgba[..., 3], plugin="pillow", extension=".png")
        (out / name).write_text(json.dumps(meta, indent=1))


def _resolution(resolution):
    if isinstance(resolution, (int, np.integer)) and not isinstance(resolution, bool):
        resolution = (resolution, resolution)
    try:
        width, height = (int(v) for v in resolution)
        ok = all(v == int(v) for v in resolution) and width >= 2 and height >= 2
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"resolution: expected an int >= 2 or (width, height), got {resolution!r}")
    return width, height


def _camera_ring(target, n_views, distance, camera_angle_x, width, height, rng):
    K = intrinsics_from_fov(camera_angle_x, width, height)
    start = rng.uniform(0.0, 360.0)
    azimuths = [(start + 360.0 * k / n_views) % 360.0 for k in range(n_views)]
    elevations = [_ELEVATIONS_DEG[k % len(_ELEVATIONS_DEG)] + rng.uniform(-_ELEVATION_JITTER_DEG, _ELEVATION_JITTER_DEG)
                  for k in range(n_views)]
    cameras = []
    for az, el in zip(np.radians(azimuths), np.radians(elevations)):
        eye = target + distance * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        cameras.append(Camera(look_at(eye, target), K, width, height))
    return cameras, (azimuths, elevations)
