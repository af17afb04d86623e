"""velogauss_core.lpips_nets: the LPIPS layer tables, weight validation and resolution order
(VG-METRIC-LPIPS). Downloads need network, so `download` is replaced by stand-ins here."""

import numpy as np
import pytest
import torch

from velogauss_core import lpips_nets
from velogauss_core.lpips_nets import (CHECKOUT_DIR, ENV_VAR, convert_state_dicts, min_image_size, read_weights,
                                      weight_shapes, weights_file)


@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net, convs, taps", [
    # torchvision alexnet().features / vgg16().features: conv index -> (out, in, kernel);
    # lpips' heads take the channels of its five ReLU taps.
    ("alex", {0: (64, 3, 11), 3: (192, 64, 5), 6: (384, 192, 3), 8: (256, 384, 3), 10: (256, 256, 3)},
     (64, 192, 384, 256, 256)),
    ("vgg", {0: (64, 3, 3), 2: (64, 64, 3), 5: (128, 64, 3), 7: (128, 128, 3), 10: (256, 128, 3),
             12: (256, 256, 3), 14: (256, 256, 3), 17: (512, 256, 3), 19: (512, 512, 3), 21: (512, 512, 3),
             24: (512, 512, 3), 26: (512, 512, 3), 28: (512, 512, 3)},
     (64, 128, 256, 512, 512)),
])
def test_weight_shapes_are_torchvision_and_lpips_layouts(net, convs, taps):
    expected = {}
    for i, (out, inp, k) in convs.items():
        expected[f"features.{i}.weight"] = (out, inp, k, k)
        expected[f"features.{i}.bias"] = (out,)
    for k, c in enumerate(taps):
        expected[f"lin{k}.model.1.weight"] = (1, c, 1, 1)
    assert weight_shapes(net) == expected


@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.skipif(not (CHECKOUT_DIR / "alex.npz").is_file(), reason=f"LPIPS weights not in {CHECKOUT_DIR}")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_shipped_weights_hold_exactly_the_expected_arrays(net):
    with np.load(CHECKOUT_DIR / f"{net}.npz") as data:
        assert {k: data[k].shape for k in data.files} == weight_shapes(net)


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_min_image_size():
    # alex: 11x11 stride-4 conv (pad 2) then two 3x3 stride-2 pools: 31 -> 7 -> 3 -> 1.
    # vgg: four 2x2 stride-2 pools before relu5_3: 16 -> 1.
    assert min_image_size("alex") == 31
    assert min_image_size("vgg") == 16


@pytest.fixture
def places(tmp_path, monkeypatch):
    """Empty stand-ins for every place weights_file looks, and a recording download."""
    folders = {name: tmp_path / name for name in ("explicit", "env", "checkout", "cache")}
    for folder in folders.values():
        folder.mkdir()
    monkeypatch.setattr(lpips_nets, "CHECKOUT_DIR", folders["checkout"])
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    folders["cache"] = tmp_path / "xdg" / "velogauss" / "lpips"
    monkeypatch.delenv(ENV_VAR, raising=False)
    calls = []

    def fake_download(net, folder):
        calls.append((net, folder))
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{net}.npz").write_bytes(b"downloaded")
        return folder / f"{net}.npz"

    monkeypatch.setattr(lpips_nets, "download", fake_download)
    return folders, calls


def _put(folder, net="alex"):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{net}.npz").write_bytes(b"weights")
    return folder / f"{net}.npz"


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_resolution_order(places, monkeypatch):
    folders, calls = places
    for name in ("explicit", "env", "checkout", "cache"):
        _put(folders[name])
    monkeypatch.setenv(ENV_VAR, str(folders["env"]))
    assert weights_file("alex", folders["explicit"]) == folders["explicit"] / "alex.npz"
    assert weights_file("alex") == folders["env"] / "alex.npz"
    monkeypatch.delenv(ENV_VAR)
    assert weights_file("alex") == folders["checkout"] / "alex.npz"
    (folders["checkout"] / "alex.npz").unlink()
    assert weights_file("alex") == folders["cache"] / "alex.npz"
    assert calls == []


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_download_into_the_cache_once(places):
    folders, calls = places
    assert weights_file("vgg") == folders["cache"] / "vgg.npz"
    assert weights_file("vgg") == folders["cache"] / "vgg.npz"
    assert calls == [("vgg", folders["cache"])]


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_an_explicit_folder_without_the_file_is_an_error(places, monkeypatch):
    folders, calls = places
    _put(folders["checkout"])
    with pytest.raises(FileNotFoundError, match="weights_dir: LPIPS weights alex.npz not found") as err:
        weights_file("alex", folders["explicit"])
    assert err.value.filename == str(folders["explicit"] / "alex.npz")
    monkeypatch.setenv(ENV_VAR, str(folders["env"]))
    with pytest.raises(FileNotFoundError, match=rf"\${ENV_VAR}: LPIPS weights alex.npz not found"):
        weights_file("alex")
    assert calls == []


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_nothing_found_and_no_network_says_how_to_provide_weights(places, monkeypatch):
    folders, _ = places

    def offline(net, folder):
        raise OSError("Network is unreachable")

    monkeypatch.setattr(lpips_nets, "download", offline)
    with pytest.raises(FileNotFoundError) as err:
        weights_file("alex")
    message = str(err.value)
    for part in ("alex.npz", str(folders["checkout"]), str(folders["cache"]), "Network is unreachable",
                 "weights_dir", "--lpips-weights", ENV_VAR):
        assert part in message


def _random_weights(net, rng):
    return {k: rng.standard_normal(shape, dtype=np.float32) for k, shape in weight_shapes(net).items()}


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_read_weights_names_a_missing_or_misshapen_key(tmp_path, rng):
    arrays = _random_weights("alex", rng)
    np.savez(tmp_path / "extra.npz", **arrays, unused=np.zeros(3))
    read = read_weights("alex", tmp_path / "extra.npz")
    assert read.keys() == arrays.keys() and all(np.array_equal(read[k], arrays[k]) for k in arrays)
    np.savez(tmp_path / "missing.npz", **{k: v for k, v in arrays.items() if k != "features.6.bias"})
    with pytest.raises(ValueError, match=r"missing.npz: missing key 'features.6.bias'; .*--lpips-weights"):
        read_weights("alex", tmp_path / "missing.npz")
    np.savez(tmp_path / "shape.npz", **{**arrays, "lin2.model.1.weight": np.zeros((1, 383, 1, 1))})
    with pytest.raises(ValueError, match=r"shape.npz: lin2.model.1.weight: expected shape \(1, 384, 1, 1\)"):
        read_weights("alex", tmp_path / "shape.npz")


@pytest.mark.spec("VG-METRIC-LPIPS")
@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_convert_state_dicts_keeps_the_feature_and_head_arrays(net, rng):
    arrays = _random_weights(net, rng)
    # torchvision's state dict also holds the classifier; lpips' the heads only.
    backbone = {k: torch.from_numpy(v) for k, v in arrays.items() if k.startswith("features.")}
    backbone["classifier.6.bias"] = torch.zeros(1000)
    heads = {k: torch.from_numpy(v) for k, v in arrays.items() if k.startswith("lin")}
    out = convert_state_dicts(net, backbone, heads)
    assert out.keys() == arrays.keys()
    assert all(out[k].dtype == np.float32 and np.array_equal(out[k], arrays[k]) for k in arrays)
    del heads["lin4.model.1.weight"]
    with pytest.raises(ValueError, match="lin4.model.1.weight"):
        convert_state_dicts(net, backbone, heads)


@pytest.mark.parametrize("net", ["squeeze", "Alex", None, 0])
def test_unknown_net_is_named(net):
    with pytest.raises(ValueError, match="^net: "):
        weights_file(net)


@pytest.mark.spec("VG-METRIC-LPIPS")
def test_read_weights_names_an_unreadable_file(tmp_path):
    (tmp_path / "alex.npz").write_bytes(b"not a zip archive")
    with pytest.raises(ValueError, match=r"alex.npz: not a readable .npz"):
        read_weights("alex", tmp_path / "alex.npz")
