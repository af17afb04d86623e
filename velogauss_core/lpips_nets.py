"""The LPIPS v0.1 networks as data: layer tables, weight files and where to find them.

spec/losses_metrics.md, VG-METRIC-LPIPS. Shared by `velogauss_ref.metrics.lpips` (NumPy)
and `velogauss_fast.metrics.lpips` (torch), so both read the same weights through the same
resolution order and the same validation. Torch is needed only to convert a downloaded
`.pth`.

Weights are one `.npz` per backbone (`alex.npz`, `vgg.npz`) of float32 arrays:
`features.N.weight` (O, I, k, k) and `features.N.bias` (O,) for every convolution, named
and laid out as in torchvision's `alexnet().features` / `vgg16().features`, and the lpips
linear heads `linK.model.1.weight` (1, C_K, 1, 1), K = 0..4. The folder is, in this order:
1. the `weights_dir` argument (`--lpips-weights DIR`);
2. `$VELOGAUSS_LPIPS_DIR`;
3. `../shared/data/lpips` beside the checkout;
4. the user cache (`$XDG_CACHE_HOME/velogauss/lpips`, default `~/.cache/velogauss/lpips`),
   filled on first use by downloading torchvision's ImageNet backbone and lpips' v0.1 heads
   and converting them to the layout above.
A folder named by 1 or 2 must hold the file (no fall-through past an explicit choice).
"""

import errno
import os
import tempfile
import urllib.request
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as onp

NETS = ("alex", "vgg")
ENV_VAR = "VELOGAUSS_LPIPS_DIR"
CHECKOUT_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "lpips"

# lpips' ScalingLayer: the [-1, 1] image is mapped to (x - SHIFT) / SCALE per RGB channel.
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)


class Layer(NamedTuple):
    """One entry of a torchvision `features` stack.

    kind "conv": `channels` outputs, square `kernel`, `stride`, zero `padding`;
    kind "relu"; kind "pool": max-pool of `kernel` x `kernel` with `stride`, no padding,
    floor mode (torchvision's MaxPool2d defaults).
    """

    kind: str
    channels: int = 0
    kernel: int = 0
    stride: int = 1
    padding: int = 0


_RELU = Layer("relu")


def _conv(channels, kernel=3, stride=1, padding=1):
    return Layer("conv", channels, kernel, stride, padding)


# `features` up to the last layer lpips uses; position i is torchvision's index i, so
# convolution i's weights are `features.i.weight`.
LAYERS = {
    "alex": (
        _conv(64, 11, 4, 2), _RELU, Layer("pool", kernel=3, stride=2),
        _conv(192, 5, 1, 2), _RELU, Layer("pool", kernel=3, stride=2),
        _conv(384), _RELU, _conv(256), _RELU, _conv(256), _RELU,
    ),
    "vgg": (
        _conv(64), _RELU, _conv(64), _RELU, Layer("pool", kernel=2, stride=2),
        _conv(128), _RELU, _conv(128), _RELU, Layer("pool", kernel=2, stride=2),
        _conv(256), _RELU, _conv(256), _RELU, _conv(256), _RELU, Layer("pool", kernel=2, stride=2),
        _conv(512), _RELU, _conv(512), _RELU, _conv(512), _RELU, Layer("pool", kernel=2, stride=2),
        _conv(512), _RELU, _conv(512), _RELU, _conv(512), _RELU,
    ),
}
# The five ReLU outputs lpips compares (its slice boundaries): relu1..relu5 of AlexNet,
# relu1_2, relu2_2, relu3_3, relu4_3, relu5_3 of VGG16.
TAPS = {"alex": (1, 4, 7, 9, 11), "vgg": (3, 8, 15, 22, 29)}

_DOWNLOADS = {
    "alex": ("https://download.pytorch.org/models/alexnet-owt-7be5be79.pth",
             "https://raw.githubusercontent.com/richzhang/PerceptualSimilarity/master/lpips/weights/v0.1/alex.pth"),
    "vgg": ("https://download.pytorch.org/models/vgg16-397923af.pth",
            "https://raw.githubusercontent.com/richzhang/PerceptualSimilarity/master/lpips/weights/v0.1/vgg.pth"),
}
# Seconds a download may stall (urllib's socket timeout) before it counts as "no network".
_DOWNLOAD_TIMEOUT_S = 60


def _how_to():
    return (f"pass a folder holding alex.npz and vgg.npz as weights_dir (--lpips-weights DIR) or in "
            f"${ENV_VAR}, or put them in {CHECKOUT_DIR}")


def check_net(net):
    """Raise ValueError naming `net` unless it is one of NETS; return it."""
    if not isinstance(net, str) or net not in NETS:
        raise ValueError(f"net: expected one of {NETS}, got {net!r}")
    return net


def weight_shapes(net):
    """{key: shape} of every array the `.npz` of `net` must hold (LAYERS and TAPS)."""
    shapes, channels, tap_channels = {}, 3, []
    for i, layer in enumerate(LAYERS[check_net(net)]):
        if layer.kind == "conv":
            shapes[f"features.{i}.weight"] = (layer.channels, channels, layer.kernel, layer.kernel)
            shapes[f"features.{i}.bias"] = (layer.channels,)
            channels = layer.channels
        if i in TAPS[net]:
            tap_channels.append(channels)
    for k, c in enumerate(tap_channels):
        shapes[f"lin{k}.model.1.weight"] = (1, c, 1, 1)
    return shapes


def min_image_size(net):
    """Smallest height (and width) every layer of `net` accepts: 31 px (alex), 16 px (vgg)."""
    size = 1
    while not _fits(net, size):
        size += 1
    return size


def _fits(net, size):
    for layer in LAYERS[net]:
        if layer.kind == "conv":
            size = (size + 2 * layer.padding - layer.kernel) // layer.stride + 1
        elif layer.kind == "pool":
            size = (size - layer.kernel) // layer.stride + 1
        if size < 1:
            return False
    return True


def cache_dir():
    """The user cache folder of downloaded weights: $XDG_CACHE_HOME/velogauss/lpips."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "velogauss" / "lpips"


def weights_file(net, weights_dir=None):
    """Path of `<net>.npz` by the resolution order of the module docstring.

    Downloads into `cache_dir()` when no folder holds the file. Raises ValueError for an
    unknown `net`, FileNotFoundError naming the file, where it was looked for and how to
    provide it when it cannot be found or downloaded.
    """
    name = f"{check_net(net)}.npz"
    env = os.environ.get(ENV_VAR)
    if weights_dir is not None or env:
        source = "weights_dir" if weights_dir is not None else f"${ENV_VAR}"
        path = Path(weights_dir if weights_dir is not None else env).expanduser() / name
        if not path.is_file():
            raise FileNotFoundError(errno.ENOENT, f"{source}: LPIPS weights {name} not found; {_how_to()}", str(path))
        return path
    for folder in (CHECKOUT_DIR, cache_dir()):
        if (folder / name).is_file():
            return folder / name
    try:
        return download(net, cache_dir())
    except (OSError, ImportError) as err:
        raise FileNotFoundError(
            errno.ENOENT,
            f"LPIPS weights {name} not found in {CHECKOUT_DIR} or {cache_dir()}, and the download "
            f"failed ({err}); {_how_to()}", name) from err


def read_weights(net, path):
    """The arrays of the `.npz` file `path` (from `weights_file`) as {key: float32 array}.

    Raises ValueError naming the file and the key when a key of `weight_shapes(net)` is
    missing or has the wrong shape, so a wrong or truncated file fails before any
    computation; keys beyond those are ignored.
    """
    try:
        with onp.load(path) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise ValueError(f"{path}: not a readable .npz of arrays ({err}); {_how_to()}") from err
    for key, shape in weight_shapes(net).items():
        if key not in arrays:
            raise ValueError(f"{path}: missing key {key!r}; expected LPIPS v0.1 {net} weights ({_how_to()})")
        if arrays[key].shape != shape:
            raise ValueError(f"{path}: {key}: expected shape {shape}, got {arrays[key].shape}")
    return {key: arrays[key].astype(onp.float32) for key in weight_shapes(net)}


def convert_state_dicts(net, backbone, heads):
    """The `.npz` arrays of `net` from torchvision's and lpips' state dicts (name -> tensor).

    Keeps the keys of `weight_shapes(net)` (torchvision's classifier and later layers are
    dropped) as float32 NumPy arrays; a missing key raises ValueError naming it.
    """
    merged = {**backbone, **heads}
    out = {}
    for key in weight_shapes(net):
        if key not in merged:
            raise ValueError(f"state dict: missing key {key!r} for LPIPS {net}")
        value = merged[key]
        out[key] = onp.asarray(value.detach().cpu().numpy() if hasattr(value, "detach") else value, onp.float32)
    return out


def download(net, folder):
    """Download torchvision's backbone and lpips' v0.1 heads of `net`, write `folder/<net>.npz`.

    Needs network access and torch (to read the `.pth` files); returns the path. The file
    is written under a temporary name and renamed, so an interrupted download leaves none.
    """
    import torch

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    state = []
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        for k, url in enumerate(_DOWNLOADS[net]):
            local = Path(tmp) / f"{k}.pth"
            with urllib.request.urlopen(url, timeout=_DOWNLOAD_TIMEOUT_S) as response:
                local.write_bytes(response.read())
            state.append(torch.load(local, map_location="cpu", weights_only=True))
        partial = Path(tmp) / f"{net}.npz"
        onp.savez(partial, **convert_state_dicts(net, *state))
        os.replace(partial, folder / f"{net}.npz")
    return folder / f"{net}.npz"
