"""Hard cases of the reference renderer (VG-QUAT, VG-COV, VG-PROJ, VG-RENDER), one named test each.

Every case must stay finite: no NaN or inf in the image, the alpha map, the projection,
or the autograd gradients w.r.t. means, quats, scales, opacities and colors. Culled
Gaussians contribute exactly nothing.
"""

import autograd.numpy as anp
import numpy as np
import pytest
from autograd import jacobian, make_vjp
from autograd.tracer import getval

from tests.ref.cameras import in_view, intrinsics
from velogauss_core.constants import ALPHA_MAX, EPS2D, NEAR_PLANE, TRANSMITTANCE_MIN
from velogauss_ref.quaternion import quat_to_rotmat
from velogauss_ref.raster import rasterize

K = intrinsics(10.0, 10.0, 4.0, 4.0)
WIDTH = HEIGHT = 8
BACKGROUND = np.array([0.2, 0.3, 0.4])
FLOAT_META = ("mean2d", "depth", "cov2d", "conic")


def scene(centres_cam, quats=None, scales=0.2, opacities=0.7):
    """Camera-space Gaussians (viewmat = I): rasterize's first five args, colours fixed."""
    means = np.asarray(centres_cam, float).reshape(-1, 3)
    n = len(means)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) if quats is None else np.asarray(quats, float)
    colors = np.random.default_rng(n).uniform(size=(n, 3))
    scales = np.broadcast_to(scales, (n, 3)).astype(float)
    return means, quats, scales, np.broadcast_to(opacities, (n,)).astype(float), colors


def render_checked(args):
    """Render with the fixed camera and assert outputs and all gradients are finite.

    Returns (image, alpha, meta, grads) with grads the VJP of a random cotangent w.r.t.
    (means, quats, scales, opacities, colors).
    """
    def render(args):
        image, alpha, meta = rasterize(*args, np.eye(4), K, WIDTH, HEIGHT, background=BACKGROUND)
        render.meta = meta
        return anp.concatenate([anp.ravel(image), anp.ravel(alpha)])

    vjp, out = make_vjp(render)(tuple(args))
    meta = {key: getval(value) for key, value in render.meta.items()}
    grads = vjp(np.random.default_rng(0).standard_normal(out.shape))
    assert np.all(np.isfinite(out))
    for key in FLOAT_META:
        assert np.all(np.isfinite(meta[key])), key
    for name, g in zip(("means", "quats", "scales", "opacities", "colors"), grads):
        assert np.all(np.isfinite(g)), name
    image = out[: HEIGHT * WIDTH * 3].reshape(HEIGHT, WIDTH, 3)
    alpha = out[HEIGHT * WIDTH * 3:].reshape(HEIGHT, WIDTH, 1)
    return image, alpha, meta, grads


def render_plain(args):
    image, alpha, _ = rasterize(*args, np.eye(4), K, WIDTH, HEIGHT, background=BACKGROUND)
    return image, alpha


def concat(a, b):
    return tuple(np.concatenate([x, y]) for x, y in zip(a, b))


@pytest.mark.spec("VG-QUAT")
@pytest.mark.parametrize("magnitude", [0.0, 1e-310], ids=["zero", "denormal"])
def test_zero_and_denormal_quaternions_are_identity_with_zero_gradient(magnitude):
    q = np.full((2, 4), magnitude)
    q[1] = [magnitude, -magnitude, magnitude, 0.0]
    np.testing.assert_array_equal(quat_to_rotmat(q), np.broadcast_to(np.eye(3), (2, 3, 3)))
    J = jacobian(quat_to_rotmat)(q)
    assert np.all(np.isfinite(J)) and np.all(J == 0.0)


@pytest.mark.spec("VG-QUAT", "VG-COV", "VG-RENDER")
@pytest.mark.parametrize("magnitude", [0.0, 1e-310], ids=["zero", "denormal"])
def test_render_with_zero_and_denormal_quaternions(magnitude):
    centres = [in_view(np.array([3.0, 4.0]), 2.0, K), in_view(np.array([5.0, 4.0]), 3.0, K)]
    args = scene(centres, quats=np.full((2, 4), magnitude), scales=np.array([0.3, 0.1, 0.2]))
    image, _, _, grads = render_checked(args)
    identity = scene(centres, scales=np.array([0.3, 0.1, 0.2]))
    np.testing.assert_array_equal(image, render_plain(identity)[0])
    assert np.all(grads[1] == 0.0)


@pytest.mark.spec("VG-QUAT")
def test_smallest_normalised_quaternion_is_a_rotation():
    # |q|^2 = 4e-22, above QUAT_ZERO_NORM_SQ: normalised, not the identity (90 deg about z).
    R = quat_to_rotmat(np.array([1e-11, 0.0, 0.0, 1e-11]))
    np.testing.assert_allclose(R, [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-12)
    assert np.all(np.isfinite(jacobian(quat_to_rotmat)(np.array([1e-11, 0.0, 0.0, 1e-11]))))


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-RENDER")
def test_tiny_scale_1e_minus_8_renders_the_dilated_splat():
    image, alpha, meta, _ = render_checked(scene([in_view(np.array([4.5, 4.5]), 2.0, K)], scales=1e-8, opacities=0.9))
    # (f s / z)^2 = 2.5e-15 px^2: the splat is the EPS2D dilation alone.
    np.testing.assert_allclose(meta["cov2d"][0], EPS2D * np.eye(2), atol=1e-12)
    np.testing.assert_allclose(alpha[4, 4, 0], 0.9, atol=1e-12)


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-RENDER")
def test_huge_scale_1e4_covers_the_image():
    image, alpha, meta, _ = render_checked(scene([[0.0, 0.0, 2.0]], scales=1e4, opacities=0.6))
    assert meta["valid"][0] and meta["radius"][0] > 1e5
    # sigma at any pixel is ~1e-9: alpha is the opacity everywhere.
    np.testing.assert_allclose(alpha, 0.6, atol=1e-6)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.parametrize(
    "depth", [-1.0, 0.0, 0.5 * NEAR_PLANE], ids=["behind_camera", "on_camera_plane", "inside_near_plane"]
)
def test_gaussian_in_front_of_the_near_plane_is_culled_and_contributes_zero(depth):
    visible = scene([in_view(np.array([3.5, 4.5]), 2.0, K)])
    culled = scene([[0.001, -0.002, depth]], scales=0.5, opacities=1.0)
    image, alpha, meta, grads = render_checked(concat(visible, culled))
    np.testing.assert_array_equal(meta["valid"], [True, False])
    np.testing.assert_array_equal(image, render_plain(visible)[0])
    for g in grads:
        assert np.all(g[1] == 0.0)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
def test_gaussian_straddling_the_near_plane():
    # Centre 1 mm behind the near plane but 1 unit wide: its mass reaches far into view,
    # yet the centre decides (culled, contributes zero).
    visible = scene([in_view(np.array([3.5, 4.5]), 2.0, K)])
    straddling = scene([[0.0, 0.0, NEAR_PLANE - 1e-3]], scales=1.0, opacities=1.0)
    image, _, meta, grads = render_checked(concat(visible, straddling))
    assert not meta["valid"][1]
    np.testing.assert_array_equal(image, render_plain(visible)[0])
    # Centre just beyond the near plane, reaching behind the camera: kept, huge and finite.
    image, alpha, meta, _ = render_checked(scene([[0.0, 0.0, NEAR_PLANE + 1e-3]], scales=0.1, opacities=0.5))
    assert meta["valid"][0]
    # cov2d ~ (f s / z)^2 ~ 8e3 px^2, so sigma <= 0.5 * 32 / 8e3 at the corners.
    np.testing.assert_allclose(alpha, 0.5, atol=1e-3)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
def test_thin_gaussian_seen_edge_on_has_a_regular_conic():
    # A disc of radius 0.5 and thickness 1e-8 on the optical axis, its plane containing the
    # axis and tilted 30 degrees about it: J W Sigma W^T J^T is a rank-1 line (det ~ 1e-15).
    c, s = np.cos(np.pi / 12), np.sin(np.pi / 12)  # quaternion of 30 deg about z
    args = scene([[0.0, 0.0, 2.0]], quats=[[c, 0.0, 0.0, s]], scales=np.array([0.5, 1e-8, 0.5]), opacities=0.8)
    image, alpha, meta, _ = render_checked(args)
    cov = meta["cov2d"][0]
    # Minor axis: the dilation alone; major axis: (f 0.5 / z)^2 + EPS2D along 30 degrees.
    major = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    expected = (10.0 * 0.5 / 2.0) ** 2 * np.outer(major, major) + EPS2D * np.eye(2)
    np.testing.assert_allclose(cov, expected, atol=1e-12)
    a, b, cc = meta["conic"][0]
    np.testing.assert_allclose(np.array([[a, b], [b, cc]]) @ cov, np.eye(2), atol=1e-12)
    assert meta["valid"][0] and alpha.max() > 0.5


@pytest.mark.spec("VG-BLEND", "VG-RENDER")
def test_64_stacked_opaque_gaussians_stop_transmittance():
    centre = in_view(np.array([4.5, 4.5]), 1.0, K) / 1.0
    centres = [centre * z for z in np.arange(1.0, 65.0)]  # the same ray, depths 1..64
    image, alpha, meta, grads = render_checked(scene(centres, scales=0.02, opacities=1.0))
    assert meta["valid"].all()
    # Everywhere, blending stopped before T fell below TRANSMITTANCE_MIN (1 - alpha
    # recovers T up to a rounding of 1 ~ 1e-16, i.e. 1e-12 relative to T).
    assert np.all(1 - alpha >= TRANSMITTANCE_MIN * (1 - 1e-9))
    # At the centre pixel only the two nearest are blended, then the pixel stops.
    np.testing.assert_allclose(alpha[4, 4, 0], 1 - (1 - ALPHA_MAX) ** 2, atol=1e-12)
    colors = scene(centres, scales=0.02, opacities=1.0)[4]
    expected = ALPHA_MAX * colors[0] + (1 - ALPHA_MAX) * ALPHA_MAX * colors[1] + (1 - ALPHA_MAX) ** 2 * BACKGROUND
    np.testing.assert_allclose(image[4, 4], expected, atol=1e-12)


@pytest.mark.spec("VG-RENDER")
def test_empty_scene_gives_the_background():
    empty = (np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)))
    image, alpha, meta = rasterize(*empty, np.eye(4), K, WIDTH, HEIGHT, background=BACKGROUND)
    np.testing.assert_array_equal(image, np.broadcast_to(BACKGROUND, (HEIGHT, WIDTH, 3)))
    np.testing.assert_array_equal(alpha, 0.0)
    assert meta["mean2d"].shape == (0, 2) and meta["valid"].shape == (0,) and meta["n_pairs"] == 0
    black, _, _ = rasterize(*empty, np.eye(4), K, WIDTH, HEIGHT)
    np.testing.assert_array_equal(black, 0.0)


@pytest.mark.spec("VG-PROJ", "VG-RENDER")
@pytest.mark.filterwarnings("ignore:Output seems independent of input")  # nothing is visible: expected
def test_every_gaussian_off_screen_gives_the_background():
    # Left of, right of, above, below the image, and far beyond the Jacobian clamp.
    uv = np.array([[-20.0, 4.0], [30.0, 4.0], [4.0, -20.0], [4.0, 30.0], [-1e4, 1e4]])
    args = scene([in_view(p, 2.0, K) for p in uv], scales=0.1, opacities=1.0)
    image, alpha, meta, grads = render_checked(args)
    assert not meta["valid"].any()
    np.testing.assert_array_equal(image, np.broadcast_to(BACKGROUND, (HEIGHT, WIDTH, 3)))
    np.testing.assert_array_equal(alpha, 0.0)
    for g in grads:
        assert np.all(g == 0.0)


def _good_args():
    return dict(zip(("means", "quats", "scales", "opacities", "colors"), scene([[0.0, 0.0, 2.0]] * 2)),
                viewmat=np.eye(4), K=K, width=WIDTH, height=HEIGHT)


def _with(name, value):
    args = _good_args()
    args[name] = value
    return args


def _poisoned(name, bad):
    args = _good_args()
    x = np.array(args[name], dtype=float)
    x.flat[-1] = bad
    args[name] = x
    return args


BAD_INPUTS = [
    *[(_poisoned(name, bad), name) for name in ("means", "quats", "scales", "opacities", "colors", "viewmat", "K")
      for bad in (np.nan, np.inf)],
    (_with("means", np.zeros((2, 2))), "means"),
    (_with("quats", np.zeros((3, 4))), "quats"),
    (_with("scales", np.zeros(3)), "scales"),
    (_with("opacities", np.ones((2, 1))), "opacities"),
    (_with("colors", np.ones((2, 4))), "colors"),
    (_with("viewmat", np.eye(3)), "viewmat"),
    (_with("K", np.eye(4)), "K"),
    (_with("width", 0), "width"),
    (_with("height", 4.0), "height"),
    ({**_good_args(), "background": np.array([0.0, np.nan, 0.0])}, "background"),
    ({**_good_args(), "background": np.zeros(4)}, "background"),
    ({**_good_args(), "sh_degree": 4}, "sh_degree"),
    ({**_good_args(), "sh_degree": 0}, "colors"),  # RGB (N, 3) given where SH (N, K, 3) is due
    ({**_with("colors", np.zeros((2, 4, 3))), "sh_degree": 2}, "colors"),  # degree 2 needs 9
]


@pytest.mark.spec("VG-RENDER")
@pytest.mark.parametrize("kwargs, name", BAD_INPUTS, ids=[f"{i}-{n}" for i, (_, n) in enumerate(BAD_INPUTS)])
def test_bad_input_raises_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        rasterize(**kwargs)
