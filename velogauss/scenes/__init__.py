"""Synthetic physics scenes: analytic textured bodies with exact motions, ray-cast to disk.

`make_scene(name, out_dir, ...)` writes a catalogue scene as a D-NeRF-layout dataset (plus
`scene.json` and `points3d.ply`) that `velogauss.data.load_scene` reads;
`make_random_scene(seed, out_dir)` does the same for a scene drawn from the random family
(`family.py`); `load_ground_truth(scene_dir)` rebuilds the `AnalyticScene` whose `position`,
`velocity` and `acceleration` are exact.
"""

from velogauss.scenes.catalog import DEFAULT_SCENE, SCENES, load_ground_truth, scene_listing
from velogauss.scenes.family import make_random_scene
from velogauss.scenes.scene import EFFECTS, AnalyticScene
from velogauss.scenes.writer import make_scene

__all__ = ["DEFAULT_SCENE", "EFFECTS", "SCENES", "AnalyticScene", "load_ground_truth", "make_random_scene",
           "make_scene", "scene_listing"]
