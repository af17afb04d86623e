"""Hard cases of velogauss_fast.rasterize (VG-QUAT, VG-COV, VG-PROJ, VG-BLEND, VG-RENDER), float32 and float64.

The cases of tests/ref/test_render_hard_cases.py, in the fast path: every one renders
without NaN or inf in the image, the alpha map, the projection or the gradients w.r.t.
means, quats, scales, opacities, colours and background, means what it should, and
(float64) agrees with the reference.
"""

import numpy as np
import pytest
import torch

from tests.fast.render_cases import (
    RTOL64,
    assert_close,
    boundary_band,
    render_gradients,
    scene_to_torch,
    to_numpy,
    to_torch,
)
from tests.ref.cameras import in_view, intrinsics
from velogauss_fast.raster import rasterize
from velogauss_ref import raster as ref
from velogauss_core.constants import ALPHA_MAX, EPS2D, NEAR_PLANE, TRANSMITTANCE_MIN

K = intrinsics(10.0, 10.0, 4.0, 4.0)
WIDTH = HEIGHT = 8
BACKGROUND = np.array([0.2, 0.3, 0.4])
DTYPES = [torch.float32, torch.float64]
GRAD_KEYS = ("means", "quats", "scales", "opacities", "colors", "background")
FLOAT_META = ("mean2d", "depth", "cov2d", "conic", "colors")
# Hand-computed values: a few roundings of O(1) quantities in the working dtype.
ATOL = {torch.float32: 1e-5, torch.float64: 1e-12}


def scene(centres_cam, quats=None, scales=0.2, opacities=0.7):
    """Camera-space Gaussians (viewmat = I) over BACKGROUND, as a rasterize keyword dict."""
    means = np.asarray(centres_cam, float).reshape(-1, 3)
    n = len(means)
    return {
        "means": means,
        "quats": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else np.asarray(quats, float),
        "scales": np.broadcast_to(scales, (n, 3)).astype(float),
        "opacities": np.broadcast_to(opacities, (n,)).astype(float),
        "colors": np.random.default_rng(n).uniform(size=(n, 3)),
        "viewmat": np.eye(4), "K": K, "width": WIDTH, "height": HEIGHT, "background": BACKGROUND,
    }


def concat(a, b):
    return {k: np.concatenate([a[k], b[k]]) if k in GRAD_KEYS[:5] else a[k] for k in a}


def render_checked(s, dtype, device, backend):
    """Render `s` in `dtype` on `device` with `backend`; assert outputs, meta and gradients are finite.

    Returns (image, alpha, meta, grads), grads the gradients of a fixed random cotangent
    w.r.t. GRAD_KEYS as a dict of tensors.
    """
    leaves = {k: to_torch(s[k], dtype, device, requires_grad=True) for k in GRAD_KEYS}
    image, alpha, meta = rasterize(**leaves, viewmat=to_torch(s["viewmat"], dtype, device),
                                   K=to_torch(s["K"], dtype, device), width=s["width"], height=s["height"],
                                   backend=backend)
    assert image.dtype == alpha.dtype == dtype
    assert torch.isfinite(image).all() and torch.isfinite(alpha).all()
    for key in FLOAT_META:
        assert torch.isfinite(meta[key]).all(), key
    rng = np.random.default_rng(0)
    cot_image = to_torch(rng.standard_normal(image.shape), dtype, device)
    cot_alpha = to_torch(rng.standard_normal(alpha.shape), dtype, device)
    grads = torch.autograd.grad((image * cot_image).sum() + (alpha * cot_alpha).sum(), list(leaves.values()))
    for key, g in zip(GRAD_KEYS, grads):
        assert torch.isfinite(g).all(), key
    return image.detach(), alpha.detach(), meta, dict(zip(GRAD_KEYS, grads))


def render_plain(s, dtype, device, backend):
    image, alpha, _ = rasterize(**scene_to_torch(s, dtype, device), backend=backend)
    return image, alpha


CENTRE = in_view(np.array([4.5, 4.5]), np.array(2.0), K)  # on the centre of pixel (4, 4) at z = 2
VISIBLE = scene([in_view(np.array([3.5, 4.5]), np.array(2.0), K)])
HARD_CASES = {
    "zero_quaternion": scene([in_view(np.array([3.0, 4.0]), np.array(2.0), K), [0.5, -0.4, 3.0]],
                             quats=np.zeros((2, 4)), scales=np.array([0.3, 0.1, 0.2])),
    "scale_1e-8": scene([CENTRE], scales=1e-8, opacities=0.9),
    "scale_1e4": scene([[0.0, 0.0, 2.0]], scales=1e4, opacities=0.6),
    "behind_camera": concat(VISIBLE, scene([[0.001, -0.002, -1.0]], scales=0.5, opacities=1.0)),
    "on_camera_plane": concat(VISIBLE, scene([[0.001, -0.002, 0.0]], scales=0.5, opacities=1.0)),
    "straddling_near_plane": concat(VISIBLE, scene([[0.0, 0.0, NEAR_PLANE - 1e-3]], scales=1.0, opacities=1.0)),
    "just_beyond_near_plane": scene([[0.0, 0.0, NEAR_PLANE + 1e-3]], scales=0.1, opacities=0.5),
    "edge_on_disc": scene([[0.0, 0.0, 2.0]], quats=[[np.cos(np.pi / 12), 0.0, 0.0, np.sin(np.pi / 12)]],
                          scales=np.array([0.5, 1e-8, 0.5]), opacities=0.8),
    "64_stacked_opaque": scene([CENTRE / 2.0 * z for z in np.arange(1.0, 65.0)], scales=0.02, opacities=1.0),
    "every_gaussian_off_screen": scene([in_view(p, np.array(2.0), K) for p in
                                        np.array([[-20.0, 4.0], [30.0, 4.0], [4.0, -20.0], [4.0, 30.0], [-1e4, 1e4]])],
                                       scales=0.1, opacities=1.0),
}


@pytest.mark.spec("VG-QUAT", "VG-COV", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("magnitude", [0.0, 1e-40], ids=["zero", "denormal"])
def test_zero_and_denormal_quaternions_render_as_the_identity(device, backend, dtype, magnitude):
    # 1e-40 is denormal in float32, where its square underflows to 0; in float64
    # |q|^2 = 4e-80 is far below QUAT_ZERO_NORM_SQ. Both mean "no rotation".
    s = dict(HARD_CASES["zero_quaternion"], quats=np.full((2, 4), magnitude))
    image, _, _, grads = render_checked(s, dtype, device, backend)
    identity, _ = render_plain(dict(s, quats=np.tile([1.0, 0.0, 0.0, 0.0], (2, 1))), dtype, device, backend)
    assert torch.equal(image, identity)
    assert torch.equal(grads["quats"], torch.zeros_like(grads["quats"]))


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_scale_1e_minus_8_renders_the_dilated_splat(device, backend, dtype):
    _, alpha, meta, _ = render_checked(HARD_CASES["scale_1e-8"], dtype, device, backend)
    # (f s / z)^2 = 2.5e-15 px^2: the splat is the EPS2D dilation alone, centred on (4, 4).
    np.testing.assert_allclose(to_numpy(meta["cov2d"][0]), EPS2D * np.eye(2), atol=ATOL[dtype])
    np.testing.assert_allclose(to_numpy(alpha[4, 4, 0]), 0.9, atol=ATOL[dtype])
    # One pixel away: 0.9 exp(-1 / (2 EPS2D)) = 0.17; diagonally: 0.9 exp(-1 / EPS2D) = 0.032.
    np.testing.assert_allclose(to_numpy(alpha[4, 5, 0]), 0.9 * np.exp(-0.5 / EPS2D), rtol=1e-5)
    np.testing.assert_allclose(to_numpy(alpha[5, 5, 0]), 0.9 * np.exp(-1.0 / EPS2D), rtol=1e-5)


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_scale_1e4_covers_the_image_with_its_opacity(device, backend, dtype):
    _, alpha, meta, _ = render_checked(HARD_CASES["scale_1e4"], dtype, device, backend)
    assert meta["valid"].tolist() == [True] and meta["radius"][0] > 1e5
    # sigma at any pixel is ~1e-9: alpha is the opacity everywhere.
    np.testing.assert_allclose(to_numpy(alpha), 0.6, atol=1e-6)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", ["behind_camera", "on_camera_plane", "straddling_near_plane"])
def test_gaussian_in_front_of_the_near_plane_contributes_nothing(device, backend, dtype, case):
    # The second Gaussian's centre is behind the near plane (the straddling one by 1 mm,
    # though 1 unit wide): culled, so the image is the first's alone, and nothing flows back.
    image, _, meta, grads = render_checked(HARD_CASES[case], dtype, device, backend)
    assert meta["valid"].tolist() == [True, False]
    assert torch.equal(image, render_plain(VISIBLE, dtype, device, backend)[0])
    for key in GRAD_KEYS[:5]:
        assert torch.equal(grads[key][1], torch.zeros_like(grads[key][1])), key


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_gaussian_just_beyond_the_near_plane_is_kept(device, backend, dtype):
    _, alpha, meta, _ = render_checked(HARD_CASES["just_beyond_near_plane"], dtype, device, backend)
    assert meta["valid"].tolist() == [True]
    # cov2d ~ (f s / z)^2 ~ 8e3 px^2, so sigma <= 0.5 * 32 / 8e3 at the corners.
    np.testing.assert_allclose(to_numpy(alpha), 0.5, atol=1e-3)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_edge_on_disc_has_a_regular_conic(device, backend, dtype):
    # Thickness 1e-8, tilted 30 degrees about the optical axis: J W Sigma W^T J^T is a
    # rank-1 line (det ~ 1e-15 before dilation); the dilation keeps the conic regular.
    _, alpha, meta, _ = render_checked(HARD_CASES["edge_on_disc"], dtype, device, backend)
    major = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    expected = (10.0 * 0.5 / 2.0) ** 2 * np.outer(major, major) + EPS2D * np.eye(2)
    cov = to_numpy(meta["cov2d"][0])
    np.testing.assert_allclose(cov, expected, atol=ATOL[dtype] * 10)  # entries ~6
    a, b, c = to_numpy(meta["conic"][0])
    # The conic's rounding is amplified by the condition number cov_max / EPS2D ~ 20.
    np.testing.assert_allclose(np.array([[a, b], [b, c]]) @ cov, np.eye(2), atol=ATOL[dtype] * 100)
    assert meta["valid"].tolist() == [True] and alpha.max() > 0.5


@pytest.mark.spec("VG-BLEND", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_64_stacked_opaque_gaussians_stop_the_pixel(device, backend, dtype):
    s = HARD_CASES["64_stacked_opaque"]
    image, alpha, meta, _ = render_checked(s, dtype, device, backend)
    assert meta["valid"].all()
    # Nowhere is T below TRANSMITTANCE_MIN (up to the rounding of 1 - alpha).
    assert (1 - alpha).min() >= TRANSMITTANCE_MIN * (1 - 1e-3)
    # The centre pixel is stopped by the first two (alpha = ALPHA_MAX each):
    # (1 - 0.99)^2 is 1.0000000000000018e-4 >= TRANSMITTANCE_MIN in float64, so the second
    # is blended; in float32 it is 9.99998e-5 < TRANSMITTANCE_MIN, so it is not (numba
    # composites in float64 whatever the dtype: blended). Either way the nearest colour
    # dominates and nothing behind the second contributes.
    front, second = s["colors"][0], s["colors"][1]
    t1 = 1 - ALPHA_MAX
    if dtype == torch.float64 or backend == "numba":
        expected = ALPHA_MAX * front + t1 * ALPHA_MAX * second + t1 * t1 * BACKGROUND
    else:
        expected = ALPHA_MAX * front + t1 * BACKGROUND
    np.testing.assert_allclose(to_numpy(image[4, 4]), expected, atol=ATOL[dtype])


@pytest.mark.spec("VG-BLEND", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", ["64_stacked_opaque", "scale_1e4", "edge_on_disc"])
def test_weights_and_final_transmittance_sum_to_one(device, backend, dtype, case):
    # White splats over white: every pixel is sum_i w_i + T = 1, stopped early or not.
    s = dict(HARD_CASES[case], background=np.ones(3))
    s["colors"] = np.ones_like(s["colors"])
    image, _ = render_plain(s, dtype, device, backend)
    np.testing.assert_allclose(to_numpy(image), 1.0, rtol=0, atol=10 * ATOL[dtype])


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_empty_scene_renders_the_background(device, backend, dtype):
    s = scene(np.zeros((0, 3)))
    image, alpha, meta, grads = render_checked(s, dtype, device, backend)
    assert torch.equal(image, to_torch(BACKGROUND, dtype, device).expand(HEIGHT, WIDTH, 3))
    assert torch.equal(alpha, torch.zeros_like(alpha))
    assert meta["mean2d"].shape == (0, 2) and meta["valid"].shape == (0,) and meta["n_pairs"] == 0
    # image = background at every pixel: d/d background is the cotangent's sum.
    cot = np.random.default_rng(0).standard_normal((HEIGHT, WIDTH, 3))
    np.testing.assert_allclose(to_numpy(grads["background"]), cot.sum((0, 1)), rtol=1e-5)
    black, _ = render_plain({k: v for k, v in s.items() if k != "background"}, dtype, device, backend)
    assert torch.equal(black, torch.zeros_like(black))


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize("dtype", DTYPES)
def test_every_gaussian_off_screen_renders_the_background(device, backend, dtype):
    # Left of, right of, above, below the image, and far beyond the Jacobian clamp.
    image, alpha, meta, grads = render_checked(HARD_CASES["every_gaussian_off_screen"], dtype, device, backend)
    assert not meta["valid"].any()
    assert torch.equal(image, to_torch(BACKGROUND, dtype, device).expand(HEIGHT, WIDTH, 3))
    assert torch.equal(alpha, torch.zeros_like(alpha))
    for key in GRAD_KEYS[:5]:
        assert torch.equal(grads[key], torch.zeros_like(grads[key])), key


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("case", list(HARD_CASES))
def test_hard_case_reference_vs_fast(device, backend, case):
    s = HARD_CASES[case]
    # The stacked case's centre pixel sits 2e-14 above the stop: banded, pinned above.
    keep = ~boundary_band(s, 1e-9)
    image_ref, alpha_ref, _ = ref.rasterize(**s)
    image, alpha = render_plain(s, torch.float64, device, backend)
    assert_close(image, image_ref, RTOL64, mask=keep)
    assert_close(alpha, alpha_ref, RTOL64, mask=keep)
    rng = np.random.default_rng(1)
    cot_image = rng.standard_normal(image_ref.shape) * keep[..., None]
    cot_alpha = rng.standard_normal(alpha_ref.shape) * keep[..., None]
    g_ref = render_gradients(s, cot_image, cot_alpha)
    g_fast = render_gradients(s, cot_image, cot_alpha, device, backend)
    for key, g in g_ref.items():
        assert_close(g_fast[key], g, RTOL64, name=f"gradient of {key}", floor=1.0)


# ---------------------------------------------------------------------------------------
# Bad input


def _good(dtype=torch.float64):
    return scene_to_torch(scene([[0.0, 0.0, 2.0]] * 2), dtype, "cpu")


def _with(name, value):
    return dict(_good(), **{name: value})


def _poisoned(name, bad):
    args = _good()
    x = args[name].clone()
    x.view(-1)[-1] = bad
    args[name] = x
    return args


# rasterize is the renderer's door: the one place a NaN or an inf in any of its tensors is
# refused (spec/conventions.md, "Bad input"); the functions it calls check shapes only.
BAD_INPUTS = [
    *[(_poisoned(name, bad), name) for name in ("means", "quats", "scales", "opacities", "colors", "viewmat", "K",
                                                "background") for bad in (float("nan"), float("inf"))],
    (_with("means", torch.zeros(2, 2, dtype=torch.float64)), "means"),
    (_with("means", np.zeros((2, 3))), "means"),  # not a tensor
    (_with("means", torch.zeros(2, 3, dtype=torch.int64)), "means"),  # not floating point
    (_with("quats", torch.zeros(3, 4, dtype=torch.float64)), "quats"),
    (_with("scales", torch.zeros(3, dtype=torch.float64)), "scales"),
    (_with("opacities", torch.ones(2, 1, dtype=torch.float64)), "opacities"),
    (_with("colors", torch.ones(2, 4, dtype=torch.float64)), "colors"),
    (_with("viewmat", torch.eye(3, dtype=torch.float64)), "viewmat"),
    (_with("K", torch.eye(4, dtype=torch.float64)), "K"),
    (_with("background", torch.zeros(4, dtype=torch.float64)), "background"),
    (_with("width", 0), "width"),
    (_with("height", 4.0), "height"),
    (_with("sh_degree", 4), "sh_degree"),
    (_with("sh_degree", 0), "colors"),  # RGB (N, 3) given where SH (N, K, 3) is due
    ({**_with("colors", torch.zeros(2, 4, 3, dtype=torch.float64)), "sh_degree": 2}, "colors"),  # needs 9
    (_with("quats", _good(torch.float32)["quats"]), "quats"),  # float32 beside float64 means
    (_with("K", _good(torch.float32)["K"]), "K"),
    (_with("background", torch.zeros(3, dtype=torch.float32)), "background"),
    (_with("backend", "cuda"), "backend"),
    (_with("backend", "Torch"), "backend"),
    (_with("backend", "gsplat"), "backend"),  # CPU tensors: gsplat's kernels need CUDA
]


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("kwargs, name", BAD_INPUTS, ids=[f"{i}-{n}" for i, (_, n) in enumerate(BAD_INPUTS)])
def test_bad_input_raises_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        rasterize(**kwargs)


@pytest.mark.spec("VG-RENDER")
@pytest.mark.skipif(not torch.cuda.is_available(), reason="a device mismatch needs a second device (CUDA)")
def test_tensor_on_another_device_raises_naming_it():
    args = {k: v.cuda() if isinstance(v, torch.Tensor) else v for k, v in _good().items()}
    args["opacities"] = args["opacities"].cpu()
    with pytest.raises(ValueError, match="^opacities:"):
        rasterize(**args)
