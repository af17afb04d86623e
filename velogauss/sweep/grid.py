"""The grid file of `velogauss sweep`: which training runs a study is made of.

A grid file is TOML. Its top-level keys are the sweep's settings; each `[[grid]]` table
names lists whose product is taken, and the sweep is the union of all its grids' points:

    out = "runs/scenes"          # the sweep's folder (`--out` wins); runs go in OUT/<run name>/
    threads = 1                  # torch/numba threads (and Ray CPUs) of each training run
    config = "base.toml"         # optional: a training config every run starts from
    [set]                        # optional: `--set` overrides of every run (one value each)
    "train.iterations" = 3000
    [scene_options]              # optional: make_scene arguments for the catalogue scenes
    resolution = 64

    [[grid]]
    threads = 2                  # optional: this grid's runs get their own thread count
    scenes = ["toss", "spin"]    # catalogue scenes, generated into OUT/data/<scene>/
    data = ["data/lego"]         # and/or scene folders on disk (relative to the grid file)
    ablations = ["full", "no-adf"]        # default ["full"]
    seeds = [0, 1, 2]                     # train.seed; default [0]
    [grid.set]                            # `--set` overrides, each a list of values
    "model.integrator" = ["rk2", "rk4"]

A point's run is named `<scene>-<ablation>-s<seed>` followed by `-<key>=<value>` for each
`[grid.set]` key (the top-level `[set]` is common to all and not part of names), so the same
point always lands in the same folder, which is what lets a sweep resume; its `group` is
the same name without the seed, what the mean ± spread over seeds is taken over. Bad
files raise ValueError naming the file and the key.
"""

import dataclasses
import itertools
import re
import tomllib
from pathlib import Path

SETTINGS = ("out", "threads", "config", "set", "scene_options", "grid")
GRID_KEYS = ("scenes", "data", "ablations", "seeds", "set", "threads")
SCENE_OPTIONS = ("resolution", "n_views", "n_times", "seed", "n_points", "n_heldout")


@dataclasses.dataclass(frozen=True)
class Point:
    """One training run of a sweep.

    `scene`: a catalogue scene name, or None when `data` (an absolute scene folder) is given;
    `overrides`: the `--set` items `("model.integrator=rk4", ...)`: the file's `[set]`, then
    the point's values of its grid's `set` table; `settings`: `(key, value)` pairs of the
    latter; `threads`: the CPUs its Ray task reserves and its torch/numba threads.
    """

    name: str
    group: str
    scene: str | None
    data: str | None
    ablation: str
    seed: int
    overrides: tuple[str, ...]
    settings: tuple[tuple[str, str], ...]
    threads: int


@dataclasses.dataclass(frozen=True)
class Sweep:
    """A parsed grid file: its settings and its points, in file order, without duplicates."""

    path: Path
    out: Path | None
    threads: int
    config: Path | None
    scene_options: dict
    points: tuple[Point, ...]


def load_grid(path):
    """Parse the grid file `path` into a `Sweep`; ValueError naming the file and key when bad."""
    from velogauss.config import toml_value
    from velogauss.scenes import SCENES

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(2, "grid file not found", str(path))
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"{path}: not valid TOML ({err})") from None
    _known(doc, SETTINGS, path, "")
    threads = _threads(doc, 1, path, "")
    options = doc.get("scene_options", {})
    if not isinstance(options, dict):
        raise ValueError(f"{path}: scene_options: expected a table")
    _known(options, SCENE_OPTIONS, path, "scene_options.")
    common = doc.get("set", {})
    if not isinstance(common, dict) or any(isinstance(v, dict) for v in common.values()):
        raise ValueError(f"{path}: set: expected a table of KEY = value")
    common = tuple(f"{k}={toml_value(v)}" for k, v in common.items())
    grids = doc.get("grid")
    if not isinstance(grids, list) or not grids or not all(isinstance(g, dict) for g in grids):
        raise ValueError(f"{path}: grid: expected at least one [[grid]] table")
    points = {}
    for i, grid in enumerate(grids):
        where = f"grid[{i}]."
        _known(grid, GRID_KEYS, path, where)
        grid_threads = _threads(grid, threads, path, where)
        scenes = _string_list(grid, "scenes", [], path, where)
        unknown = [s for s in scenes if s not in SCENES]
        if unknown:
            raise ValueError(f"{path}: {where}scenes: unknown scene(s) {unknown}; choose from {', '.join(SCENES)}")
        folders = [str((path.parent / d).resolve()) for d in _string_list(grid, "data", [], path, where)]
        if not scenes and not folders:
            raise ValueError(f"{path}: {where}: needs `scenes` or `data` (a non-empty list)")
        ablations = _string_list(grid, "ablations", ["full"], path, where)
        seeds = grid.get("seeds", [0])
        if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) and not isinstance(s, bool)
                                                                for s in seeds):
            raise ValueError(f"{path}: {where}seeds: expected a non-empty list of integers, got {seeds!r}")
        sets = grid.get("set", {})
        if not isinstance(sets, dict):
            raise ValueError(f"{path}: {where}set: expected a table of KEY = [values]")
        for key, values in sets.items():
            if not isinstance(values, list) or not values:
                raise ValueError(f"{path}: {where}set.{key}: expected a non-empty list of values, got {values!r}")
        sources = [(s, None) for s in scenes] + [(None, d) for d in folders]
        keys = list(sets)
        for (scene, data), ablation, seed, values in itertools.product(sources, ablations, seeds,
                                                                      itertools.product(*sets.values())):
            swept = tuple(f"{k}={toml_value(v)}" for k, v in zip(keys, values))
            stem = scene or Path(data).name
            name = "-".join([stem, ablation, f"s{seed}"] + [_slug(o) for o in swept])
            group = "-".join([stem, ablation] + [_slug(o) for o in swept])
            settings = tuple((k, str(v)) for k, v in zip(keys, values))
            point = Point(name, group, scene, data, ablation, seed, common + swept, settings, grid_threads)
            if points.setdefault(name, point) != point:
                raise ValueError(f"{path}: two different points are both named {name!r}; rename a data folder")
    out = doc.get("out")
    config = doc.get("config")
    for key, value in (("out", out), ("config", config)):
        if value is not None and not isinstance(value, str):
            raise ValueError(f"{path}: {key}: expected a path string, got {value!r}")
    return Sweep(path, None if out is None else Path(out), threads,
                 None if config is None else (path.parent / config).resolve(), dict(options), tuple(points.values()))


def _threads(table, default, path, where):
    threads = table.get("threads", default)
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"{path}: {where}threads: expected a positive integer, got {threads!r}")
    return threads


def _known(table, allowed, path, where):
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise ValueError(f"{path}: {where}{unknown[0]}: unknown key; expected one of {', '.join(allowed)}")


def _string_list(grid, key, default, path, where):
    values = grid.get(key, default)
    if not isinstance(values, list) or not all(isinstance(v, str) for v in values) or (key in grid and not values):
        raise ValueError(f"{path}: {where}{key}: expected a non-empty list of strings, got {values!r}")
    return values


def _slug(override):
    """`model.integrator="rk4"` → `model.integrator=rk4`: safe in a folder name."""
    return re.sub(r"[^A-Za-z0-9._=+-]+", "_", override.replace('"', "")).strip("_")
