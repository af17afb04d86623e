"""The training targets: 8-bit pixels, float images and SSIM halves kept within a byte budget."""

import numpy as np
import torch

from velogauss.data import Camera, Frame
from velogauss.data.cameras import intrinsics_from_fov, look_at
from velogauss.train.targets import TrainingTargets
from velogauss_fast.metrics import ssim_target

SIZE = 16  # >= the 11-tap SSIM window


def _frames(rng, n):
    camera = Camera(look_at(np.array([0.0, -4.0, 1.0]), np.zeros(3)), intrinsics_from_fov(0.7, SIZE, SIZE), SIZE, SIZE)
    return [Frame(rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8), i / n, camera, f"f{i}") for i in range(n)]


def test_targets_equal_the_images_and_their_ssim_halves_whether_kept_or_not(rng):
    frames = _frames(rng, 5)
    per_image = 9 * 4 * SIZE * SIZE
    targets = TrainingTargets(frames, "cpu", budget=2 * per_image + per_image // 2)
    assert targets.kept == 2 and len(targets) == 5
    for _ in range(2):  # a second pass reads the kept ones back
        for i, frame in enumerate(frames):
            image, target = targets[i]
            expected = torch.as_tensor(frame.pixels.astype(np.float64) / 255.0, dtype=torch.float32)
            assert torch.equal(image, expected)
            for got, want in zip(target, ssim_target(expected)):
                assert torch.equal(got, want)
    assert sorted(targets._cache) == [0, 1]  # the budget bounds what stays between steps
    assert targets[0] is targets[0] and targets[4] is not targets[4]


def test_a_budget_below_one_image_keeps_none(rng):
    targets = TrainingTargets(_frames(rng, 3), "cpu", budget=100)
    assert targets.kept == 0
    targets[0], targets[1]
    assert targets._cache == {}
