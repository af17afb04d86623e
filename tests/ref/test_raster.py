"""velogauss_ref.raster: VG-ALPHA (splat opacity), VG-BLEND (blending), VG-RENDER (image)."""

import autograd.numpy as anp
import numpy as np
import pytest
from autograd import grad
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.cameras import in_view, intrinsics, rigid_viewmat, to_world
from tests.ref.gradcheck import check_grads_fd
from velogauss_core.constants import ALPHA_MAX, ALPHA_MIN, EPS2D, TRANSMITTANCE_MIN
from velogauss_ref.covariance import covariance_3d
from velogauss_ref.projection import project_gaussians
from velogauss_ref.raster import blend, rasterize, splat_alpha
from velogauss_ref.sh import C0

# Sums of a few O(1) float64 products.
TOL = 1e-12
IDENTITY_QUAT = np.array([1.0, 0.0, 0.0, 0.0])


def isotropic_scene(centres_cam, s, opacities, colors):
    """Camera-space Gaussians (viewmat = I) with isotropic std s: rasterize's first five args."""
    n = len(centres_cam)
    return (np.asarray(centres_cam, float), np.tile(IDENTITY_QUAT, (n, 1)), np.full((n, 3), s),
            np.asarray(opacities, float), np.asarray(colors, float))


# ---------------------------------------------------------------------------------------
# VG-ALPHA


@pytest.mark.spec("VG-ALPHA")
def test_splat_alpha_values():
    pixel = np.array([[1.5, 2.5], [2.5, 4.5], [1.5, 2.5]])
    mean2d = np.array([[1.5, 2.5], [1.5, 2.5], [1.5, 2.5]])
    conic = np.array([[1.0, 0.0, 1.0], [2.0, 0.5, 1.0], [1.0, 0.0, 1.0]])
    opacity = np.array([0.5, 0.8, 1.0])
    # d = 0; d = (1, 2): sigma = (2 * 1 + 1 * 4) / 2 + 0.5 * 2 = 4; d = 0 with o = 1: clamped.
    expected = [0.5, 0.8 * np.exp(-4.0), ALPHA_MAX]
    np.testing.assert_allclose(splat_alpha(pixel, mean2d, conic, opacity), expected, atol=TOL)


@pytest.mark.spec("VG-ALPHA")
def test_alpha_below_alpha_min_is_skipped():
    # o exp(-sigma) just above and just below 1/255 at sigma = 1/2 (d = (1, 0), unit conic).
    o = ALPHA_MIN * np.exp(0.5) * np.array([1.001, 0.999])
    alpha = splat_alpha(np.array([1.0, 0.0]), np.zeros(2), np.array([1.0, 0.0, 1.0]), o)
    np.testing.assert_allclose(alpha, [ALPHA_MIN * 1.001, 0.0], atol=TOL)


@pytest.mark.spec("VG-ALPHA")
def test_negative_sigma_is_skipped():
    # Indefinite conic (b^2 > ac): sigma = (1 + 1) / 2 - 2 = -1 at d = (1, 1); o exp(1) would clamp to 0.99.
    alpha = splat_alpha(np.array([1.0, 1.0]), np.zeros(2), np.array([1.0, -2.0, 1.0]), np.array(0.9))
    assert alpha == 0.0


@pytest.mark.spec("VG-ALPHA")
def test_very_negative_sigma_has_zero_gradient_not_nan():
    # sigma = -1000: o exp(-sigma) overflows to inf, but the splat is skipped and its
    # gradient w.r.t. every input is exactly zero.
    args = (np.array([10.0, 10.0]), np.array([0.0, 0.0]), np.array([1.0, -20.0, 1.0]), np.array(0.5))
    assert splat_alpha(*args) == 0.0
    for k in range(4):
        g = grad(lambda x: splat_alpha(*args[:k], x, *args[k + 1:]))(args[k])
        assert np.all(g == 0.0), k


@pytest.mark.spec("VG-ALPHA")
def test_splat_alpha_broadcasts():
    pixels = np.stack(np.meshgrid(np.arange(4) + 0.5, np.arange(3) + 0.5), -1)  # (3, 4, 2)
    mean2d, conic, opacity = np.array([1.0, 1.0]), np.array([0.5, 0.1, 0.4]), np.array(0.7)
    alpha = splat_alpha(pixels, mean2d, conic, opacity)
    assert alpha.shape == (3, 4)
    np.testing.assert_allclose(alpha[2, 3], splat_alpha(pixels[2, 3], mean2d, conic, opacity), atol=TOL)


def alpha_margin(pixel, mean2d, conic, opacity):
    """Smallest |log| distance of o exp(-sigma) to ALPHA_MIN and ALPHA_MAX (a test guard)."""
    (du, dv), (a, b, c) = np.moveaxis(pixel - mean2d, -1, 0), np.moveaxis(conic, -1, 0)
    sigma = 0.5 * (a * du**2 + c * dv**2) + b * du * dv
    log_raw = np.log(opacity) - sigma
    return np.min(np.abs(np.stack([log_raw - np.log(ALPHA_MIN), log_raw - np.log(ALPHA_MAX)])))


@st.composite
def splats(draw, n=6):
    """n splats with positive-definite conics near their pixels, opacities in [0.05, 1]."""
    pixel = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(0.0, 8.0)))
    offset = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(-2.0, 2.0)))
    L = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.2, 1.5)))
    # conic = M M^T with M lower triangular (positive diagonal): positive definite.
    conic = np.stack([L[:, 0] ** 2, L[:, 0] * (L[:, 1] - 0.85), (L[:, 1] - 0.85) ** 2 + L[:, 2] ** 2], -1)
    opacity = draw(hnp.arrays(np.float64, n, elements=st.floats(0.05, 1.0)))
    return pixel, pixel - offset, conic, opacity


@pytest.mark.spec("VG-ALPHA")
@given(splats(), st.integers(0, 2**32 - 1))
def test_splat_alpha_gradient(args, seed):
    assume(alpha_margin(*args) > 1e-3)  # no splat within 0.1% of a clamp or skip threshold
    check_grads_fd(splat_alpha, args, (0, 1, 2, 3), np.random.default_rng(seed))


# ---------------------------------------------------------------------------------------
# VG-BLEND

unit_colors = hnp.arrays(np.float64, (6, 3), elements=st.floats(0.0, 1.0))
alphas_in_range = hnp.arrays(np.float64, 6, elements=st.one_of(st.just(0.0), st.floats(ALPHA_MIN, ALPHA_MAX)))


@pytest.mark.spec("VG-BLEND")
def test_two_splats_over_background():
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    bg = np.array([0.0, 0.0, 1.0])
    color, T = blend(colors, np.array([0.6, 0.5]), bg)
    np.testing.assert_allclose(color, [0.6, 0.4 * 0.5, 0.4 * 0.5], atol=TOL)
    np.testing.assert_allclose(T, 0.2, atol=TOL)


@pytest.mark.spec("VG-BLEND")
def test_no_splats_shows_background():
    color, T = blend(np.zeros((0, 3)), np.zeros(0), np.array([0.1, 0.2, 0.3]))
    np.testing.assert_array_equal(color, [0.1, 0.2, 0.3])
    assert T == 1.0


@pytest.mark.spec("VG-BLEND")
@given(unit_colors, alphas_in_range)
def test_weights_and_final_transmittance_sum_to_one(colors, alphas):
    # White splats over a white background: the colour is sum_i alpha_i T_i + T, whether
    # or not the early termination fired.
    color, T = blend(np.ones_like(colors), alphas, np.ones(3))
    np.testing.assert_allclose(color, 1.0, atol=TOL)
    assert T >= TRANSMITTANCE_MIN


@pytest.mark.spec("VG-BLEND")
@given(unit_colors, alphas_in_range, st.integers(0, 5))
def test_zero_alpha_splat_changes_nothing(colors, alphas, k):
    without = blend(np.delete(colors, k, 0), np.delete(alphas, k), np.full(3, 0.5))
    alphas = alphas.copy()
    alphas[k] = 0.0
    with_zero = blend(colors, alphas, np.full(3, 0.5))
    np.testing.assert_allclose(with_zero[0], without[0], atol=TOL)
    np.testing.assert_allclose(with_zero[1], without[1], atol=TOL)


@pytest.mark.spec("VG-BLEND")
def test_opaque_splats_terminate_early():
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]])
    bg = np.array([0.3, 0.3, 0.3])
    alphas = np.full(4, ALPHA_MAX)
    color, T = blend(colors, alphas, bg)
    # (1 - 0.99)^2 = 1.0000000000000018e-4 >= TRANSMITTANCE_MIN: two splats are blended;
    # the third would bring T to 1e-6 and stops the pixel, so it and the fourth are unseen.
    t1 = 1 - ALPHA_MAX
    np.testing.assert_allclose(color, ALPHA_MAX * colors[0] + ALPHA_MAX * t1 * colors[1] + t1 * t1 * bg, atol=TOL)
    np.testing.assert_allclose(T, t1 * t1, rtol=TOL)
    other = colors.copy()
    other[2:] = 0.5
    np.testing.assert_array_equal(blend(other, alphas, bg)[0], color)


@pytest.mark.spec("VG-BLEND")
def test_transmittance_exactly_at_the_minimum_is_still_blended():
    # ((1 - 0.8) (1 - 0.977)) (1 - a3) rounds to exactly TRANSMITTANCE_MIN in float64: the
    # stop is strict (T_next < TRANSMITTANCE_MIN), so the third splat is blended and the
    # fourth, which would halve T, ends the pixel.
    a3 = 0.9782608695652174
    assert (1.0 * (1 - 0.8)) * (1 - 0.977) * (1 - a3) == TRANSMITTANCE_MIN
    colors = np.eye(4)[:, :3]
    color, T = blend(colors, np.array([0.8, 0.977, a3, 0.5]), np.zeros(3))
    assert T == TRANSMITTANCE_MIN
    np.testing.assert_allclose(color, [0.8, 0.2 * 0.977, 0.2 * 0.023 * a3], atol=TOL)


def transmittance_margin(alphas):
    """Smallest |log| distance of the running T (1 - alpha_i) to TRANSMITTANCE_MIN (a test guard)."""
    log_t = np.cumsum(np.log1p(-alphas))
    return np.min(np.abs(log_t - np.log(TRANSMITTANCE_MIN)))


@pytest.mark.spec("VG-BLEND")
@given(unit_colors, hnp.arrays(np.float64, 6, elements=st.floats(0.01, 0.98)), unit_colors, st.integers(0, 2**32 - 1))
def test_blend_gradient(colors, alphas, bg, seed):
    assume(transmittance_margin(alphas) > 1e-3)

    def f(colors, alphas, background):
        color, T = blend(colors, alphas, background)
        return anp.concatenate([color, anp.reshape(T, (1,))])

    check_grads_fd(f, (colors, alphas, bg[0]), (0, 1, 2), np.random.default_rng(seed))


# ---------------------------------------------------------------------------------------
# VG-RENDER

K8 = intrinsics(10.0, 10.0, 4.0, 4.0)


@pytest.mark.spec("VG-RENDER")
def test_single_gaussian_matches_hand_computed_pixel():
    s, z, o = 0.2, 2.0, 0.8
    color, bg = np.array([0.9, 0.5, 0.1]), np.array([0.2, 0.3, 0.4])
    args = isotropic_scene([[0.0, 0.0, z]], s, [o], [color])
    image, alpha, meta = rasterize(*args, np.eye(4), K8, 8, 8, background=bg)
    assert image.shape == (8, 8, 3) and alpha.shape == (8, 8, 1)
    var = (10.0 * s / z) ** 2 + EPS2D  # 1.3 px^2; radius ceil(3 sqrt(1.4)) = 4
    assert meta["radius"][0] == 4
    # Pixel (row 4, column 5) has centre (5.5, 4.5): offset (1.5, 0.5) from the mean (4, 4).
    a = o * np.exp(-0.5 * (1.5**2 + 0.5**2) / var)
    np.testing.assert_allclose(image[4, 5], a * color + (1 - a) * bg, atol=TOL)
    np.testing.assert_allclose(alpha[4, 5, 0], a, atol=TOL)
    # Pixel (0, 0) is inside the box (offset (-3.5, -3.5)) but o exp(-9.4) < 1/255: skipped.
    np.testing.assert_array_equal(image[0, 0], bg)
    assert alpha[0, 0, 0] == 0.0


@pytest.mark.spec("VG-RENDER")
def test_background_shows_where_nothing_covers():
    bg = np.array([0.2, 0.3, 0.4])
    # A small splat centred on pixel (1, 1): radius ceil(3 sqrt(0.3 + 0.1)) = 2.
    mu = in_view(np.array([1.5, 1.5]), 2.0, K8)
    args = isotropic_scene([mu], 1e-4, [0.9], [[1.0, 1.0, 1.0]])
    image, alpha, meta = rasterize(*args, np.eye(4), K8, 8, 8, background=bg)
    assert meta["radius"][0] == 2
    assert image[1, 1, 0] > 0.9
    np.testing.assert_array_equal(image[4:, :], np.broadcast_to(bg, (4, 8, 3)))
    np.testing.assert_array_equal(image[:, 4:], np.broadcast_to(bg, (8, 4, 3)))
    np.testing.assert_array_equal(alpha[4:, 4:], 0.0)


@pytest.mark.spec("VG-RENDER")
def test_opaque_front_gaussian_hides_what_is_behind_up_to_the_leak():
    # Mean on the centre of pixel (4, 4) with opacity 1: alpha there is the clamp 0.99.
    centres = [in_view(np.array([4.5, 4.5]), z, K8) for z in (2.0, 3.0)]
    front, behind = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 1.0])
    image, alpha, _ = rasterize(*isotropic_scene(centres, 0.1, [1.0, 1.0], [front, behind]), np.eye(4), K8, 8, 8)
    np.testing.assert_allclose(alpha[4, 4, 0], 1 - (1 - ALPHA_MAX) ** 2, atol=TOL)
    # The 1% leak: what is behind contributes at most (1 - ALPHA_MAX) of the pixel.
    np.testing.assert_allclose(image[4, 4], ALPHA_MAX * front + (1 - ALPHA_MAX) * ALPHA_MAX * behind, atol=TOL)
    assert np.max(np.abs(image[4, 4] - ALPHA_MAX * front)) <= 1 - ALPHA_MAX


@pytest.mark.spec("VG-RENDER", "VG-BLEND")
def test_two_opaque_gaussians_stop_the_pixel():
    centres = [in_view(np.array([4.5, 4.5]), z, K8) for z in (2.0, 3.0, 4.0)]
    colors = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    image, alpha, _ = rasterize(*isotropic_scene(centres, 0.1, [1.0, 1.0, 1.0], colors), np.eye(4), K8, 8, 8)
    t1 = 1 - ALPHA_MAX
    np.testing.assert_allclose(image[4, 4], ALPHA_MAX * colors[0] + t1 * ALPHA_MAX * colors[1], atol=TOL)
    np.testing.assert_allclose(alpha[4, 4, 0], 1 - t1 * t1, atol=TOL)


@pytest.mark.spec("VG-RENDER")
def test_gaussians_are_blended_by_depth_not_input_order():
    centres = [in_view(np.array([4.5, 4.5]), z, K8) for z in (3.0, 2.0)]
    scene = isotropic_scene(centres, 0.1, [0.5, 0.5], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    image, _, _ = rasterize(*scene, np.eye(4), K8, 8, 8)
    flipped = [a[::-1] for a in scene]
    np.testing.assert_allclose(rasterize(*flipped, np.eye(4), K8, 8, 8)[0], image, atol=TOL)
    # Nearer (green, z = 2) first: 0.5 green, then 0.5 * 0.5 red.
    np.testing.assert_allclose(image[4, 4], [0.25, 0.5, 0.0], atol=TOL)


@pytest.mark.spec("VG-RENDER")
def test_equal_depths_keep_input_order():
    centre = in_view(np.array([4.5, 4.5]), 2.0, K8)
    scene = isotropic_scene([centre, centre], 0.1, [0.5, 0.5], [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(rasterize(*scene, np.eye(4), K8, 8, 8)[0][4, 4], [0.5, 0.25, 0.0], atol=TOL)


@pytest.mark.spec("VG-RENDER")
def test_many_equal_depths_keep_input_order():
    # 20 Gaussians at depths 2, 3, 2, 3, ...: enough ties that an unstable sort (numpy's
    # introsort beyond 16 elements) reorders them. Opacity 0.1 keeps T >= 0.9^20.
    n = 20
    depths = np.tile([2.0, 3.0], n // 2)
    centres = [in_view(np.array([4.5, 4.5]), z, K8) for z in depths]
    colors = np.random.default_rng(5).uniform(size=(n, 3))
    image, _, _ = rasterize(*isotropic_scene(centres, 0.1, [0.1] * n, colors), np.eye(4), K8, 8, 8)
    order = np.concatenate([np.arange(0, n, 2), np.arange(1, n, 2)])  # depth 2 first, each in input order
    expected = sum(colors[g] * 0.1 * 0.9**k for k, g in enumerate(order))
    np.testing.assert_allclose(image[4, 4], expected, atol=TOL)


@pytest.mark.spec("VG-RENDER")
def test_pixel_centre_on_the_box_edge_is_covered():
    # Mean at (1.5, 4.5) on the optical axis; x variance A = 0.69 + EPS2D = 0.99 (the major
    # axis), so r = ceil(3 sqrt(0.99)) = 3 and the centre (4.5, 4.5) of pixel (4, 4) lies
    # exactly on the right edge u + r. There alpha = exp(-9 / (2 A)) ~ 0.0106 > ALPHA_MIN.
    K = intrinsics(10.0, 10.0, 1.5, 4.5)
    s_x = np.sqrt(0.69) * 2.0 / 10.0
    args = isotropic_scene([[0.0, 0.0, 2.0]], 0.05, [1.0], [[1.0, 1.0, 1.0]])
    args = (args[0], args[1], np.array([[s_x, 0.05, 0.05]]), *args[3:])
    _, alpha, meta = rasterize(*args, np.eye(4), K, 8, 8)
    assert meta["radius"][0] == 3 and meta["mean2d"][0, 0] + 3 == 4.5
    np.testing.assert_allclose(alpha[4, 4, 0], np.exp(-9.0 / (2 * meta["cov2d"][0, 0, 0])), rtol=1e-12)
    assert alpha[4, 5, 0] == 0.0


@pytest.mark.spec("VG-RENDER", "VG-SH")
def test_sh_degree_zero_matches_rgb_colours():
    rng = np.random.default_rng(3)
    centres = in_view(rng.uniform(1.0, 7.0, (3, 2)), rng.uniform(2.0, 4.0, 3), K8)
    sh = rng.normal(size=(3, 16, 3))
    base = (centres, rng.normal(size=(3, 4)), rng.uniform(0.05, 0.3, (3, 3)), rng.uniform(0.2, 0.9, 3))
    viewmat = rigid_viewmat(np.array([0.1, -0.2, 0.05]), np.array([0.3, 0.1, 0.2]))
    means = to_world(centres, viewmat)
    image_sh, _, meta = rasterize(means, *base[1:], sh, viewmat, K8, 8, 8, sh_degree=0)
    rgb = np.maximum(C0 * sh[:, 0] + 0.5, 0.0)
    image_rgb, _, _ = rasterize(means, *base[1:], rgb, viewmat, K8, 8, 8)
    np.testing.assert_allclose(image_sh, image_rgb, atol=TOL)
    np.testing.assert_allclose(meta["colors"], rgb, atol=TOL)


@pytest.mark.spec("VG-RENDER", "VG-PROJ")
def test_meta_carries_the_projection():
    rng = np.random.default_rng(4)
    scene = (in_view(rng.uniform(1.0, 7.0, (3, 2)), rng.uniform(2.0, 4.0, 3), K8), rng.normal(size=(3, 4)),
             rng.uniform(0.05, 0.3, (3, 3)), rng.uniform(0.2, 0.9, 3), rng.uniform(size=(3, 3)))
    _, _, meta = rasterize(*scene, np.eye(4), K8, 8, 8)
    proj = project_gaussians(scene[0], covariance_3d(scene[1], scene[2]), np.eye(4), K8, 8, 8)
    for key, value in proj.items():
        np.testing.assert_array_equal(meta[key], value)
    # n_pairs counts the pixel centres inside each valid box (all of them here).
    u, v, r = proj["mean2d"][:, 0], proj["mean2d"][:, 1], proj["radius"]
    centres = np.arange(8) + 0.5
    inside_u = (centres[None] >= (u - r)[:, None]) & (centres[None] <= (u + r)[:, None])
    inside_v = (centres[None] >= (v - r)[:, None]) & (centres[None] <= (v + r)[:, None])
    assert meta["n_pairs"] == int(np.sum(inside_u.sum(1) * inside_v.sum(1)))


def render_margin(scene, viewmat, K, width, height):
    """Distance of a tiny scene to every discontinuity of the renderer (a test guard).

    Box edges and radius roundings in pixels, alpha thresholds in log units, depth ties;
    inf-like when nothing is near. Blending never terminates in these scenes (opacity
    <= 0.9 and 3 Gaussians keep T >= 1e-3), so the transmittance stop is not checked.
    """
    means, quats, scales, opacities, _ = scene
    proj = project_gaussians(means, covariance_3d(quats, scales), viewmat, K, width, height)
    if not proj["valid"].all():
        return 0.0
    cov = proj["cov2d"]
    b = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    extent = 3.0 * np.sqrt(b + np.sqrt(np.maximum(0.01, b * b - det)))
    margins = [np.min(np.abs(extent - np.round(extent))), np.min(np.abs(np.diff(np.sort(proj["depth"]))))]
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    pixels = np.stack([jj, ii], -1).reshape(-1, 1, 2)
    r = proj["radius"][:, None]
    for edge in (proj["mean2d"] - r, proj["mean2d"] + r):
        margins.append(np.min(np.abs(pixels - edge[None])))
    margins.append(alpha_margin(pixels, proj["mean2d"][None], proj["conic"][None], opacities[None]))
    return min(margins)


@st.composite
def tiny_scenes(draw, n=3, width=8, height=8):
    """n Gaussians inside the view of a random rigid 8x8 camera, opacities <= 0.9."""
    viewmat = rigid_viewmat(draw(hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0))),
                            draw(hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))))
    uv = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(1.0, 7.0)))
    z = draw(hnp.arrays(np.float64, n, elements=st.floats(2.0, 4.0)))
    means = to_world(in_view(uv, z, K8), viewmat)
    quats = draw(hnp.arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0)).filter(
        lambda q: np.all(np.sum(q * q, -1) >= 0.01)))
    scales = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.05, 0.3)))
    opacities = draw(hnp.arrays(np.float64, n, elements=st.floats(0.2, 0.9)))
    colors = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.0, 1.0)))
    return (means, quats, scales, opacities, colors), viewmat


@pytest.mark.spec("VG-RENDER")
@settings(max_examples=8)  # each example costs one ~1 s VJP through the per-pixel loop
@given(tiny_scenes(), st.integers(0, 2**32 - 1))
def test_rasterize_gradient(scene_and_camera, seed):
    scene, viewmat = scene_and_camera
    # 1e-3 px / log units is ~100x the largest move of any quantity over the probe segment.
    assume(render_margin(scene, viewmat, K8, 8, 8) > 1e-3)

    def render(*scene):
        image, alpha, _ = rasterize(*scene, viewmat, K8, 8, 8)
        return anp.concatenate([anp.ravel(image), anp.ravel(alpha)])

    check_grads_fd(render, scene, (0, 1, 2, 3, 4), np.random.default_rng(seed))


@pytest.mark.spec("VG-RENDER", "VG-PROJ")
@pytest.mark.parametrize("var_px", [0.25, 1.0])
def test_antialiased_mode_keeps_a_splats_integral_through_the_dilation(var_px):
    # One isotropic splat of screen variance var_px (before EPS2D) in a 24 x 24 image. Its
    # alpha summed over the pixels is a Riemann sum of o exp(-r^2 / (2 v)), i.e. o 2 pi v,
    # less the tail that the 3-sigma box and ALPHA_MIN cut (0.5-0.8% here) and an aliasing
    # error of e^(-2 pi^2 v) (1e-3 at the smallest v), hence 2%. "classic" renders the
    # dilated variance v = var_px + EPS2D: a splat four times thinner than a pixel gets
    # 2.2 times its mass. "antialiased" dilates by MIP_FILTER_VARIANCE and scales the
    # opacity by compensation = var_px / v, which leaves the undilated integral o 2 pi var_px.
    f, z, o = 10.0, 2.0, 0.9
    s = np.sqrt(var_px) * z / f
    K = intrinsics(f, f, 12.0, 12.0)
    scene = isotropic_scene([[0.0, 0.0, z]], s, [o], [[1.0, 1.0, 1.0]])
    sums = {mode: rasterize(*scene, np.eye(4), K, 24, 24, mode=mode)[1].sum() for mode in ("classic", "antialiased")}
    assert sums["classic"] == pytest.approx(o * 2 * np.pi * (var_px + EPS2D), rel=0.02)
    assert sums["antialiased"] == pytest.approx(o * 2 * np.pi * var_px, rel=0.02)


@pytest.mark.spec("VG-RENDER")
def test_rasterize_names_a_bad_mode():
    scene = isotropic_scene([[0.0, 0.0, 2.0]], 0.1, [0.5], [[1.0, 1.0, 1.0]])
    with pytest.raises(ValueError, match="mode"):
        rasterize(*scene, np.eye(4), K8, 8, 8, mode="mip")
