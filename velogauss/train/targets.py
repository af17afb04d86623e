"""The training images as the steps compare with them (spec/data.md, "Memory").

Every training frame's 8-bit pixels sit on the device; the float image and its half of SSIM
(`velogauss_fast.metrics.ssim_target`, 9 floats a pixel) are kept, once first used, for the
first images that fit in TARGET_CACHE_BYTES, and recomputed at each use for the others. A
scene whose images all fit trains as if every target were computed up front.
"""

import torch

from velogauss_fast.metrics import ssim_target
from velogauss_core.constants import TARGET_CACHE_BYTES

# float32 bytes per pixel of a kept target: the image, the window means and the squares, 3 channels each.
_TARGET_BYTES_PER_PIXEL = 9 * 4


class TrainingTargets:
    """`targets[i]` -> (image (H, W, 3) float32 in [0, 1], its `SSIMTarget`) of training frame i.

    frames: the training `Frame`s; device: where the steps run; budget: bytes of kept targets
    (TARGET_CACHE_BYTES)."""

    def __init__(self, frames, device, budget=TARGET_CACHE_BYTES):
        self.pixels = [torch.as_tensor(f.pixels, device=device) for f in frames]
        per_image = _TARGET_BYTES_PER_PIXEL * frames[0].camera.width * frames[0].camera.height if frames else 1
        self.kept = min(len(frames), int(budget // per_image))
        self._cache = {}

    def __len__(self):
        return len(self.pixels)

    def image(self, index):
        """The float image (H, W, 3) of training frame i alone: the kept one, else converted
        without its half of SSIM (the step's PSNR needs no more)."""
        if index in self._cache:
            return self._cache[index][0]
        return self.pixels[index].to(torch.float32) / 255.0

    def __getitem__(self, index):
        if index in self._cache:
            return self._cache[index]
        image = self.image(index)
        target = (image, ssim_target(image))
        if index < self.kept:
            self._cache[index] = target
        return target
