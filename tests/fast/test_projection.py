"""velogauss_fast.projection: VG-PROJ against velogauss_ref.projection."""

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fast.render_cases import (
    DEVICE_SETTINGS,
    check_agreement,
    check_float32,
    gradcheck_fn,
    projection_doubt,
    to_torch,
)
from tests.ref.cameras import in_view, intrinsics, rigid_viewmat, to_world
from velogauss_fast.projection import project_gaussians
from velogauss_ref import projection as ref
from velogauss_core.constants import EPS2D, FAR_PLANE, FRUSTUM_GUARD, MIP_FILTER_VARIANCE, NEAR_PLANE
from velogauss_ref.covariance import covariance_3d

FLOAT_KEYS = ("mean2d", "depth", "cov2d", "conic", "compensation")
DTYPES = [torch.float32, torch.float64]
# Hand-computed expectations in the working dtype: a few roundings of O(1) values.
ATOL = {torch.float32: 1e-5, torch.float64: 1e-12}


def float_outputs(project):
    """project_gaussians as a function of its arguments returning the float outputs only."""
    def fn(*args):
        proj = project(*args)
        return tuple(proj[k] for k in FLOAT_KEYS)

    return fn


@st.composite
def projection_inputs(draw, n=5):
    """(means, Sigma, viewmat, K, width, height): n Gaussians seen by a random rigid camera.

    Centres project anywhere in [-10, 26] px (on and off screen, inside and beyond the
    Jacobian clamp) at depths in [0.05, 6] or culled ones in [-1, 0.005]: never within
    a factor 5 of NEAR_PLANE, so float32 and float64 cull the same Gaussians (the
    near-plane test itself is pinned below).
    """
    width, height = draw(st.integers(4, 16)), draw(st.integers(4, 16))
    fx = draw(st.floats(5.0, 20.0))
    K = intrinsics(fx, fx * draw(st.floats(0.8, 1.25)), draw(st.floats(0.0, width)), draw(st.floats(0.0, height)))
    viewmat = rigid_viewmat(draw(hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0))),
                            draw(hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))))
    uv = draw(hnp.arrays(np.float64, (n, 2), elements=st.floats(-10.0, 26.0)))
    z = draw(hnp.arrays(np.float64, n, elements=st.one_of(st.floats(0.05, 6.0), st.floats(-1.0, 0.005))))
    quats = draw(hnp.arrays(np.float64, (n, 4), elements=st.floats(-1.0, 1.0)).filter(
        lambda q: np.all(np.sum(q * q, -1) >= 0.01)))
    scales = draw(hnp.arrays(np.float64, (n, 3), elements=st.floats(0.01, 0.5)))
    means = to_world(in_view(uv, z, K), viewmat)
    return means, covariance_3d(quats, scales), viewmat, K, width, height


@pytest.mark.spec("VG-PROJ")
@DEVICE_SETTINGS
@given(projection_inputs(), st.integers(0, 2**32 - 1))
def test_project_gaussians_reference_vs_fast(device, inputs, seed):
    # Gradients w.r.t. means, Sigma and viewmat. Not K: the reference's autograd has no
    # VJP for np.clip's bounds, which depend on K (gradcheck below covers K).
    # Floor 1: pixels, px^2 and depths are O(1) quantities; a centre on the principal point
    # at cx = 0 has |mean2d| ~ 1e-16 of rounding noise, which no relative test can compare.
    # Observed over 300 random inputs: float64 <= 3e-14, float32 <= 1e-5 (mean2d).
    check_agreement(float_outputs(ref.project_gaussians), float_outputs(project_gaussians), inputs,
                    diff=(0, 1, 2), device=device, seed=seed, floor=1.0)
    check_float32(float_outputs(ref.project_gaussians), float_outputs(project_gaussians), inputs, device, floor=1.0)


@pytest.mark.spec("VG-PROJ")
@DEVICE_SETTINGS
@given(projection_inputs())
def test_radius_and_validity_match_the_reference(device, inputs):
    width, height = inputs[4:]
    proj_ref = ref.project_gaussians(*inputs)
    # delta: float64 reproduces the reference to ~1e-15; float32 moves u, v and the extent
    # by ~1e-6 relative, far inside 1e-4.
    for dtype, delta in ((torch.float64, 1e-9), (torch.float32, 1e-4)):
        proj = project_gaussians(*(to_torch(a, dtype, device) for a in inputs[:4]), width, height)
        assert proj["radius"].dtype == torch.int64 and proj["valid"].dtype == torch.bool
        depth_doubt, screen_doubt, radius_doubt = projection_doubt(proj_ref, width, height, delta)
        sure = ~(depth_doubt | screen_doubt | radius_doubt)
        np.testing.assert_array_equal(proj["radius"].cpu().numpy()[~radius_doubt], proj_ref["radius"][~radius_doubt])
        np.testing.assert_array_equal(proj["valid"].cpu().numpy()[sure], proj_ref["valid"][sure])


@pytest.mark.spec("VG-PROJ")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("eps2d", [EPS2D, MIP_FILTER_VARIANCE])
def test_gaussian_on_the_optical_axis(device, dtype, eps2d):
    # Isotropic s = 0.2 at z = 2 seen with f = 10: (f s / z)^2 = 1 px^2 plus eps2d;
    # lambda_max = 1 + eps2d + sqrt(EIGEN_DISCRIMINANT_FLOOR), 1.4 or 1.2: radius
    # ceil(3 sqrt(lambda_max)) = 4 either way; compensation sqrt(det before / det after the
    # dilation) = 1 / (1 + eps2d).
    var = 1.0 + eps2d
    proj = project_gaussians(torch.tensor([[0.0, 0.0, 2.0]], dtype=dtype, device=device),
                             0.04 * torch.eye(3, dtype=dtype, device=device)[None],
                             torch.eye(4, dtype=dtype, device=device),
                             to_torch(intrinsics(10.0, 10.0, 4.0, 3.0), dtype, device), 8, 6, eps2d)
    expected = {"mean2d": [[4.0, 3.0]], "depth": [2.0], "cov2d": [var * np.eye(2)], "conic": [[1 / var, 0.0, 1 / var]],
                "compensation": [1 / var]}
    for key, value in expected.items():
        assert proj[key].dtype == dtype and proj[key].device.type == device
        np.testing.assert_allclose(proj[key].cpu().numpy(), value, rtol=0, atol=ATOL[dtype], err_msg=key)
    assert proj["radius"].tolist() == [4] and proj["valid"].tolist() == [True]


@pytest.mark.spec("VG-PROJ")
@pytest.mark.parametrize("dtype", DTYPES)
def test_jacobian_is_clamped_at_the_off_centre_frustum_limits(device, dtype):
    # Principal point (3, 2) in an 8 x 6 image, f = 10: the clamp limits of x/z are
    # (8 - 3)/10 + 0.3 * 0.4 = 0.62 to the right and 3/10 + 0.12 = 0.42 to the left;
    # of y/z, (6 - 2)/10 + 0.3 * 0.3 = 0.49 down and 2/10 + 0.09 = 0.29 up.
    K = intrinsics(10.0, 10.0, 3.0, 2.0)
    lim = {"right": 0.62, "left": 0.42, "down": 0.49, "up": 0.29}
    assert np.isclose(lim["right"], 0.5 + FRUSTUM_GUARD * 0.4) and np.isclose(lim["up"], 0.2 + FRUSTUM_GUARD * 0.3)
    # Camera-space centres at x/z or y/z = +-10, far beyond the limits, isotropic s = 0.2, z = 2.
    centres = np.array([[20.0, 0.0, 2.0], [-20.0, 0.0, 2.0], [0.0, 20.0, 2.0], [0.0, -20.0, 2.0]])
    Sigma = 0.04 * torch.eye(3, dtype=dtype, device=device).expand(4, 3, 3)
    proj = project_gaussians(to_torch(centres, dtype, device), Sigma, torch.eye(4, dtype=dtype, device=device),
                             to_torch(K, dtype, device), 8, 6)
    # Sigma = s^2 I: cov2d = s^2 (f/z)^2 (I + t t^T) + EPS2D I with t the clamped (x/z, y/z).
    base = 0.04 * (10.0 / 2.0) ** 2
    expected = [np.diag([base * (1 + lim["right"] ** 2), base]), np.diag([base * (1 + lim["left"] ** 2), base]),
                np.diag([base, base * (1 + lim["down"] ** 2)]), np.diag([base, base * (1 + lim["up"] ** 2)])]
    np.testing.assert_allclose(proj["cov2d"].cpu().numpy(), np.array(expected) + EPS2D * np.eye(2),
                               rtol=0, atol=ATOL[dtype])
    assert not proj["valid"].any()  # 100 px off screen with a radius of a few px


@pytest.mark.spec("VG-PROJ")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("z", [-1.0, 0.0, 0.5 * NEAR_PLANE, 2 * FAR_PLANE],
                         ids=["behind", "camera_plane", "inside_near_plane", "beyond_far_plane"])
def test_depth_culled_gaussians_are_finite_with_finite_gradients(device, dtype, z, rng):
    means = torch.tensor([[0.1, -0.1, z], [0.0, 0.0, 2.0]], dtype=dtype, device=device, requires_grad=True)
    Sigma = (0.04 * torch.eye(3, dtype=dtype, device=device)).expand(2, 3, 3).clone().requires_grad_()
    viewmat = torch.eye(4, dtype=dtype, device=device, requires_grad=True)
    K = to_torch(intrinsics(10.0, 10.0, 4.0, 4.0), dtype, device, requires_grad=True)
    proj = project_gaussians(means, Sigma, viewmat, K, 8, 8)
    assert proj["valid"].tolist() == [False, True]
    outputs = [proj[k] for k in FLOAT_KEYS]
    for key, out in zip(FLOAT_KEYS, outputs):
        assert torch.isfinite(out).all(), key
    total = sum((o * to_torch(rng.standard_normal(o.shape), dtype, device)).sum() for o in outputs)
    grads = torch.autograd.grad(total, (means, Sigma, viewmat, K))
    for g in grads:
        assert torch.isfinite(g).all()


@pytest.mark.spec("VG-PROJ")
@pytest.mark.parametrize("dtype", DTYPES)
def test_off_screen_culling_by_the_box(device, dtype):
    # The splat of test_gaussian_on_the_optical_axis (radius 4) in an 8 x 8 image, its
    # centre placed 0.25 px inside or outside the reach of its box on every side.
    K = intrinsics(10.0, 10.0, 4.0, 4.0)
    uv = np.array([[-3.75, 4.0], [-4.25, 4.0], [11.75, 4.0], [12.25, 4.0],
                   [4.0, -3.75], [4.0, -4.25], [4.0, 11.75], [4.0, 12.25]])
    proj = project_gaussians(to_torch(in_view(uv, np.full(8, 2.0), K), dtype, device),
                             0.04 * torch.eye(3, dtype=dtype, device=device).expand(8, 3, 3),
                             torch.eye(4, dtype=dtype, device=device), to_torch(K, dtype, device), 8, 8)
    assert proj["radius"].tolist() == [4] * 8
    assert proj["valid"].tolist() == [True, False] * 4


@pytest.mark.spec("VG-PROJ")
def test_project_gaussians_gradcheck(device):
    # Three Gaussians well inside the view: no clamp or culling within the probe steps.
    rng = np.random.default_rng(4)
    K = intrinsics(12.0, 11.0, 4.2, 3.9)
    viewmat = rigid_viewmat(np.array([0.2, -0.1, 0.3]), np.array([0.1, 0.2, -0.1]))
    means = to_world(in_view(rng.uniform(2.0, 6.0, (3, 2)), rng.uniform(1.5, 3.0, 3), K), viewmat)
    Sigma = covariance_3d(rng.normal(size=(3, 4)), rng.uniform(0.05, 0.3, (3, 3)))
    gradcheck_fn(float_outputs(project_gaussians), (means, Sigma, viewmat, K, 8, 8), diff=(0, 1, 2, 3), device=device)


def _args(**changes):
    args = {"means": torch.zeros(2, 3), "Sigma": torch.eye(3).expand(2, 3, 3), "viewmat": torch.eye(4),
            "K": torch.eye(3), "width": 8, "height": 8}
    args.update(changes)
    return args


@pytest.mark.spec("VG-PROJ")
@pytest.mark.parametrize(
    "args, name",
    [
        (_args(means=torch.zeros(2, 2)), "means"),
        (_args(Sigma=torch.eye(3).expand(3, 3, 3)), "Sigma"),
        (_args(viewmat=torch.eye(3)), "viewmat"),
        (_args(viewmat=torch.eye(4, dtype=torch.int64)), "viewmat"),
        (_args(K=torch.eye(4)), "K"),
        (_args(width=0), "width"),
        (_args(height=4.0), "height"),
        (_args(eps2d=-0.1), "eps2d"),
        (_args(eps2d=float("nan")), "eps2d"),
        (_args(means=np.zeros((2, 3))), "means"),
    ],
)
def test_bad_input_names_the_argument(args, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        project_gaussians(**args)
