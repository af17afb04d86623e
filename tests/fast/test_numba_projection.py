"""velogauss_fast.backends.numba_projection: the numba backend's compiled preparation of a
view (VG-COV, VG-PROJ, VG-SH and the composited opacities), against the reference and the
torch path. Whole renders through it run in tests/fast/test_raster.py and
test_render_hard_cases.py (the `backend` parametrization's "numba")."""

from fractions import Fraction

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fast.render_cases import (
    assert_close,
    check_agreement,
    check_float32,
    gradcheck_fn,
    projection_doubt,
    random_scene,
    scene_to_torch,
    to_torch,
)
from tests.ref.cameras import in_view, intrinsics, rigid_viewmat, to_world
from velogauss_core.rendering import dilation, splat_opacities
from velogauss_fast.backends.numba_projection import prepare_numba
from velogauss_fast.raster import prepare_torch, rasterize
from velogauss_ref import projection as ref_projection
from velogauss_ref import sh as ref_sh
from velogauss_ref.covariance import covariance_3d as ref_covariance

FLOAT_KEYS = ("mean2d", "depth", "cov2d", "conic", "compensation")
MODES = ("classic", "antialiased")


def ref_prepare(means, quats, scales, opacities, colors, viewmat, K, width, height, sh_degree, mode):
    """The reference's VG-COV, VG-PROJ, VG-SH and opacities: the float outputs, then rgb and
    the composited opacities."""
    proj = ref_projection.project_gaussians(means, ref_covariance(quats, scales), viewmat, K, width, height,
                                            dilation(mode))
    rgb = colors if sh_degree is None else ref_sh.sh_to_color(colors, ref_sh.viewing_directions(means, viewmat),
                                                              sh_degree)
    return (*(proj[k] for k in FLOAT_KEYS), rgb, splat_opacities(opacities, proj["compensation"], mode))


def fast_outputs(prepare):
    """`prepare` (prepare_numba or prepare_torch) with ref_prepare's outputs."""
    def fn(*args):
        proj, rgb, opacities = prepare(*args)
        return (*(proj[k] for k in FLOAT_KEYS), rgb, opacities)

    return fn


@st.composite
def view_inputs(draw, n=5, near_thresholds=True):
    """prepare's arguments: n Gaussians seen by a random rigid camera, colours RGB or SH of
    degree 0-3, either mode.

    As tests/fast/test_projection.py's inputs: centres anywhere in [-10, 26] px (on and off
    screen, inside and beyond the Jacobian clamp), at depths in [0.05, 6] or culled ones in
    [-1, -0.05] (behind the camera: a centre near it has a viewing direction, and so a
    colour, that float32 rounding turns anywhere; the camera centre itself is a hard case
    below); with near_thresholds False, centres stay inside the image and the clamp
    and at depths in [1, 4] (finite differences must not step across a threshold).
    """
    width, height = draw(st.integers(4, 16)), draw(st.integers(4, 16))
    fx = draw(st.floats(5.0, 20.0))
    K = intrinsics(fx, fx * draw(st.floats(0.8, 1.25)), draw(st.floats(0.3 * width, 0.7 * width)),
                   draw(st.floats(0.3 * height, 0.7 * height)))
    viewmat = rigid_viewmat(draw(hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0))),
                            draw(hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))))
    if near_thresholds:
        uv = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(-10.0, 26.0)))
        z = draw(hnp.arrays(np.float64, n, elements=st.one_of(st.floats(0.05, 6.0), st.floats(-1.0, -0.05))))
    else:
        uv = np.stack([draw(hnp.arrays(np.float64, n, elements=st.floats(1.0, width - 1.0))),
                       draw(hnp.arrays(np.float64, n, elements=st.floats(1.0, height - 1.0)))], -1)
        z = draw(hnp.arrays(np.float64, n, elements=st.floats(1.0, 4.0)))
    quats = draw(hnp.arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0)).filter(
        lambda q: np.all(np.sum(q * q, -1) >= 0.01)))
    scales = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.01, 0.5)))
    opacities = draw(hnp.arrays(np.float64, n, elements=st.floats(0.05, 0.95)))
    sh_degree = draw(st.sampled_from([None, 0, 1, 2, 3]))
    shape = (n, 3) if sh_degree is None else (n, (sh_degree + 1) ** 2 + draw(st.integers(0, 2)), 3)
    colors = draw(hnp.arrays(np.float64, shape, elements=st.floats(-1.0, 1.0)))
    means = to_world(in_view(uv, z, K), viewmat)
    return means, quats, scales, opacities, colors, viewmat, K, width, height, sh_degree, draw(st.sampled_from(MODES))


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-SH")
@given(view_inputs(), st.integers(0, 2**32 - 1))
def test_prepare_numba_reference_vs_fast(inputs, seed):
    # Gradients w.r.t. means, quats, scales, opacities and colours (the camera gets none in
    # the kernels: rasterize takes the torch path when it needs one). Floor 1 as in
    # test_projection: pixels, px^2, depths and colours are O(1).
    check_agreement(ref_prepare, fast_outputs(prepare_numba), inputs, diff=(0, 1, 2, 3, 4), device="cpu",
                    seed=seed, floor=1.0, grad_floor=1.0)
    check_float32(ref_prepare, fast_outputs(prepare_numba), inputs, "cpu", floor=1.0)


@pytest.mark.spec("VG-PROJ")
@given(view_inputs())
def test_radius_and_validity_match_the_reference(inputs):
    means, quats, scales, _, _, viewmat, K, width, height, _, mode = inputs
    proj_ref = ref_projection.project_gaussians(means, ref_covariance(quats, scales), viewmat, K, width, height,
                                                dilation(mode))
    for dtype, delta in ((torch.float64, 1e-9), (torch.float32, 1e-4)):
        args = [to_torch(a, dtype) if isinstance(a, np.ndarray) else a for a in inputs]
        proj, _, _ = prepare_numba(*args)
        assert proj["radius"].dtype == torch.int64 and proj["valid"].dtype == torch.bool
        depth_doubt, screen_doubt, radius_doubt = projection_doubt(proj_ref, width, height, delta)
        sure = ~(depth_doubt | screen_doubt | radius_doubt)
        np.testing.assert_array_equal(proj["radius"].numpy()[~radius_doubt], proj_ref["radius"][~radius_doubt])
        np.testing.assert_array_equal(proj["valid"].numpy()[sure], proj_ref["valid"][sure])


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-SH")
@given(view_inputs(near_thresholds=False))
def test_prepare_numba_gradcheck(inputs):
    # Centres inside the image and the clamp, 1-4 deep: no threshold within a 1e-6 step.
    # The colours' clamp at 0 is kept out of reach: the constant band gives C0 + 0.5 = 0.78,
    # and the others, at most 15 coefficients of 0.05 times basis values below 0.6, 0.45.
    inputs = list(inputs)
    if inputs[9] is not None:
        inputs[4] = 0.05 * inputs[4]
        inputs[4][:, 0] = 1.0
    gradcheck_fn(fast_outputs(prepare_numba), inputs, diff=(0, 1, 2, 3, 4), device="cpu")


def camera_centre(viewmat, rounding):
    """-W^T t (3,), each entry a three-term dot product rounded as a CPU may round it:
    "sequential" (three products, two additions, each rounded: no FMA) or "fma" (a chain of
    fused multiply-adds, fma(W2k, t2, fma(W1k, t1, W0k t0)), in exact rational arithmetic)."""
    W, t = viewmat[:3, :3], viewmat[:3, 3]
    centre = np.empty(3)
    for k in range(3):
        if rounding == "sequential":
            centre[k] = -(float(W[0, k] * t[0]) + float(W[1, k] * t[1]) + float(W[2, k] * t[2]))
        else:
            acc = float(Fraction(W[0, k]) * Fraction(t[0]))
            for j in (1, 2):
                acc = float(Fraction(W[j, k]) * Fraction(t[j]) + Fraction(acc))
            centre[k] = -acc
    return centre


@pytest.mark.spec("VG-COV", "VG-PROJ", "VG-SH")
@pytest.mark.parametrize("rounding", ["sequential", "fma"])
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("sh_degree", [None, 1, 3])
def test_hard_cases_match_the_torch_path(mode, sh_degree, rounding):
    # Degenerate Gaussians where a derivative is a convention: zero and denormal
    # quaternions (the identity, no gradient), a centre at the camera (culled; its viewing
    # direction is +z, no gradient through it), flat discs (scale 1e-9), centres far
    # outside the clamp and behind the camera. The numba preparation must give the torch
    # path's outputs and gradients for them, not merely finite ones. The camera centre is
    # rounded with and without FMA: an Intel CPU's compiled path once contracted to FMA and
    # saw a direction of 1e-17 where torch saw an exact 0 (VIEW_DIRECTION_MIN).
    rng = np.random.default_rng(7)
    scene = random_scene(rng, 60, 24, 18, scale_px=(0.05, 8.0), margin=40.0, depth=(-1.0, 4.0), sh_degree=sh_degree)
    scene["scales"][::5, 2] = 1e-9
    scene["quats"][1] = 0.0
    scene["quats"][2] = 1e-200
    scene["means"][3] = camera_centre(scene["viewmat"], rounding)
    outs = []
    for prepare in (prepare_torch, prepare_numba):
        t = scene_to_torch(scene, torch.float64, "cpu", requires_grad=True)
        keys = ("means", "quats", "scales", "opacities", "colors")
        proj, rgb, opacities = prepare(*(t[k] for k in keys), t["viewmat"], t["K"], scene["width"], scene["height"],
                                       sh_degree, mode)
        floats = [proj[k] for k in FLOAT_KEYS] + [rgb, opacities]
        cot = np.random.default_rng(1)
        loss = sum((f * torch.as_tensor(cot.standard_normal(f.shape))).sum() for f in floats)
        grads = torch.autograd.grad(loss, [t[k] for k in keys], allow_unused=True)
        outs.append((floats, proj["radius"], proj["valid"], [torch.zeros_like(t[k]) if g is None else g
                                                             for g, k in zip(grads, keys)]))
    (f_t, r_t, v_t, g_t), (f_n, r_n, v_n, g_n) = outs
    assert torch.equal(r_n, r_t) and torch.equal(v_n, v_t)
    assert not v_n[3]
    for k, (a, b) in enumerate(zip(f_n, f_t)):
        assert_close(a, b.detach().numpy(), 1e-12, name=f"output {k}", floor=1.0)
    if sh_degree is not None:
        plus_z = ref_sh.sh_to_color(scene["colors"][3:4], np.array([[0.0, 0.0, 1.0]]), sh_degree)
        for rgb in (f_n[5], f_t[5]):
            np.testing.assert_array_equal(rgb[3:4].detach().numpy(), plus_z)
    # Flat discs: conic and compensation are ill-conditioned (det ~ eps2d times a tiny
    # variance), so their gradients agree to the conditioning, ~1e-11 (observed <= 4e-11).
    for name, a, b in zip(("means", "quats", "scales", "opacities", "colors"), g_n, g_t):
        assert_close(a, b.numpy(), 1e-9, name=f"gradient of {name}", floor=1.0)
    for i in (1, 2):
        assert torch.all(g_n[1][i] == 0), "a zero quaternion passes no gradient"


@pytest.mark.spec("VG-RENDER")
def test_a_camera_with_a_gradient_renders_through_the_torch_path():
    # The kernels give the camera no gradient; rasterize must not silently drop it.
    scene = random_scene(np.random.default_rng(3), 30, 16, 12)
    grads = {}
    for backend in ("torch", "numba"):
        t = scene_to_torch(scene, torch.float64, "cpu")
        viewmat = t["viewmat"].clone().requires_grad_()
        image, _, _ = rasterize(t["means"], t["quats"], t["scales"], t["opacities"], t["colors"], viewmat, t["K"],
                                scene["width"], scene["height"], backend=backend)
        (grads[backend],) = torch.autograd.grad(image.square().sum(), viewmat)
    assert grads["numba"].abs().max() > 0
    assert_close(grads["numba"], grads["torch"].numpy(), 1e-10, name="viewmat gradient", floor=1.0)
