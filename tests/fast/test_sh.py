"""velogauss_fast.sh: VG-SH against velogauss_ref.sh."""

import numpy as np
import pytest
import torch
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.fast.render_cases import DEVICE_SETTINGS, check_agreement, check_float32, gradcheck_fn, to_torch
from tests.ref.cameras import rigid_viewmat
from velogauss_core.constants import VIEW_DIRECTION_MIN
from velogauss_fast.sh import sh_to_color, viewing_directions
from velogauss_ref import sh as ref

DTYPES = [torch.float32, torch.float64]

coefficients = hnp.arrays(np.float64, (5, 16, 3), elements=st.floats(-2.0, 2.0))
# |d| >= 0.03: normalising is well conditioned in float32 (the zero direction has its own test).
directions = hnp.arrays(np.float64, (5, 3), elements=st.floats(-3.0, 3.0)).filter(
    lambda d: np.all(np.sum(d * d, -1) >= 1e-3))


def clamp_margin(sh, dirs, degree):
    """Smallest |sum_lm c_lm Y_lm + 0.5| over all outputs: the distance to the clamp at 0."""
    unit = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    Y = ref.sh_basis(unit, degree)
    return np.min(np.abs(np.einsum("nk,nkc->nc", Y, sh[:, : (degree + 1) ** 2]) + 0.5))


@pytest.mark.spec("VG-SH")
@DEVICE_SETTINGS
@given(coefficients, directions, st.integers(0, 3), st.integers(0, 2**32 - 1))
def test_sh_to_color_reference_vs_fast(device, sh, dirs, degree, seed):
    # The two sum the bands in different orders: still ~1e-15 of the O(1) colours, inside
    # RTOL64. Away from the clamp at 0 (whose kink both treat alike, but at which autograd
    # and torch pick different one-sided gradients).
    assume(clamp_margin(sh, dirs, degree) > 1e-9)
    # Floor 1: colours are O(1); float32 cannot represent what float64 calls tiny.
    # Observed over 300 random inputs: float64 <= 3e-16, float32 <= 2.2e-7.
    check_agreement(ref.sh_to_color, sh_to_color, (sh, dirs, degree), diff=(0, 1), device=device, seed=seed,
                    floor=1.0)
    check_float32(ref.sh_to_color, sh_to_color, (sh, dirs, degree), device, floor=1.0)


@pytest.mark.spec("VG-SH")
@DEVICE_SETTINGS
@given(hnp.arrays(np.float64, (4, 3), elements=st.floats(-3.0, 3.0)),
       hnp.arrays(np.float64, 3, elements=st.floats(-3.0, 3.0)),
       hnp.arrays(np.float64, 3, elements=st.floats(-2.0, 2.0)), st.integers(0, 2**32 - 1))
def test_viewing_directions_reference_vs_fast(device, means, rotvec, t, seed):
    check_agreement(ref.viewing_directions, viewing_directions, (means, rigid_viewmat(rotvec, t)), diff=(0, 1),
                    device=device, seed=seed, floor=1.0)


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize("dtype", DTYPES)
def test_camera_centre_has_zero_viewing_direction(device, dtype):
    viewmat = rigid_viewmat(np.array([0.3, -0.2, 0.5]), np.array([1.0, -2.0, 0.5]))
    centre = -viewmat[:3, :3].T @ viewmat[:3, 3]
    means = np.stack([centre, centre + [0.0, 0.0, 2.0]])
    d = viewing_directions(to_torch(means, dtype, device), to_torch(viewmat, dtype, device))
    atol = 1e-6 if dtype == torch.float32 else 1e-14  # rounding of |t| ~ 2
    np.testing.assert_allclose(d.cpu().numpy(), [[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]], atol=atol)


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize("dtype", DTYPES)
def test_degree_zero_is_the_constant_band(device, dtype, rng):
    sh = to_torch(rng.normal(size=(6, 4, 3)), dtype, device)
    dirs = to_torch(rng.normal(size=(6, 3)), dtype, device)
    expected = torch.clamp(ref.C0 * sh[:, 0] + 0.5, min=0.0)
    assert torch.equal(sh_to_color(sh, dirs, 0), expected)


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("degree", [0, 1, 2])
def test_coefficients_beyond_the_degree_are_ignored(device, dtype, degree, rng):
    sh = to_torch(rng.normal(size=(5, 16, 3)), dtype, device, requires_grad=True)
    dirs = to_torch(rng.normal(size=(5, 3)), dtype, device)
    n = (degree + 1) ** 2
    rgb = sh_to_color(sh, dirs, degree)
    assert torch.equal(rgb, sh_to_color(sh[:, :n], dirs, degree))
    (g,) = torch.autograd.grad(rgb.sum(), sh)
    assert torch.equal(g[:, n:], torch.zeros_like(g[:, n:]))


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize("dtype", DTYPES)
def test_direction_length_does_not_matter_and_zero_means_plus_z(device, dtype, rng):
    sh = to_torch(rng.normal(scale=0.1, size=(3, 16, 3)), dtype, device)
    # The third is shorter than VIEW_DIRECTION_MIN: rounding noise of a camera centre.
    dirs = torch.tensor([[0.0, 0.0, 0.0], [0.3, -0.4, 1.2], [0.5 * VIEW_DIRECTION_MIN, 0.0, 0.0]], dtype=dtype,
                        device=device, requires_grad=True)
    rgb = sh_to_color(sh, dirs, 3)
    plus_z = torch.tensor([[0.0, 0.0, 1.0]], dtype=dtype, device=device)
    assert torch.equal(rgb[[0, 2]], sh_to_color(sh[[0, 2]], plus_z.expand(2, 3), 3))
    tol = 1e-6 if dtype == torch.float32 else 1e-14  # a few roundings of O(1) colours
    torch.testing.assert_close(sh_to_color(sh[1:2], 7.5 * dirs[1:2].detach(), 3), rgb[1:2], rtol=0, atol=tol)
    # The short directions are replaced by a constant: no gradient reaches them, and none is NaN.
    (g,) = torch.autograd.grad((rgb * to_torch(rng.normal(size=(3, 3)), dtype, device)).sum(), dirs)
    assert torch.isfinite(g).all() and torch.equal(g[[0, 2]], torch.zeros_like(g[[0, 2]]))
    assert g[1].abs().sum() > 0


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize("dtype", DTYPES)
def test_negative_colour_clamps_to_zero_without_gradient(device, dtype):
    sh = torch.zeros(1, 1, 3, dtype=dtype, device=device)
    sh[0, 0] = torch.tensor([-5.0, 0.0, 5.0])  # C0 c + 0.5: -0.91, 0.5, 1.91
    sh.requires_grad_()
    rgb = sh_to_color(sh, torch.ones(1, 3, dtype=dtype, device=device), 0)
    np.testing.assert_allclose(rgb.detach().cpu().numpy(), [[0.0, 0.5, ref.C0 * 5 + 0.5]], rtol=1e-6)
    (g,) = torch.autograd.grad(rgb.sum(), sh)
    np.testing.assert_allclose(g[0, 0].cpu().numpy(), [0.0, ref.C0, ref.C0], rtol=1e-6)


@pytest.mark.spec("VG-SH")
def test_sh_to_color_gradcheck(device):
    rng = np.random.default_rng(5)
    # Coefficients near 0 keep every colour near 0.5, far from the clamp.
    sh, dirs = rng.normal(scale=0.05, size=(3, 16, 3)), rng.normal(size=(3, 3))
    gradcheck_fn(lambda s, d: sh_to_color(s, d, 3), (sh, dirs), diff=(0, 1), device=device)


@pytest.mark.spec("VG-SH")
def test_viewing_directions_gradcheck(device):
    rng = np.random.default_rng(7)
    viewmat = rigid_viewmat(rng.normal(size=3), rng.normal(size=3))
    gradcheck_fn(viewing_directions, (rng.normal(size=(3, 3)), viewmat), diff=(0, 1), device=device)


@pytest.mark.spec("VG-SH")
@pytest.mark.parametrize(
    "fn, args, name",
    [
        (sh_to_color, (torch.zeros(2, 16, 3), torch.ones(2, 3), 4), "degree"),
        (sh_to_color, (torch.zeros(2, 16, 3), torch.ones(2, 3), -1), "degree"),
        (sh_to_color, (torch.zeros(2, 16, 3), torch.ones(2, 3), 1.0), "degree"),
        (sh_to_color, (torch.zeros(2, 16, 3), torch.ones(2, 3), True), "degree"),
        (sh_to_color, (torch.zeros(2, 8, 3), torch.ones(2, 3), 2), "sh"),
        (sh_to_color, (torch.zeros(2, 16), torch.ones(2, 3), 0), "sh"),
        (sh_to_color, (torch.zeros(2, 16, 3), torch.ones(3, 3), 0), "dirs"),
        (sh_to_color, (torch.zeros(2, 16, 3), np.ones((2, 3)), 0), "dirs"),
        (viewing_directions, (torch.zeros(2, 3), torch.eye(3)), "viewmat"),
        (viewing_directions, (torch.zeros(2, 4), torch.eye(4)), "means"),
    ],
)
def test_bad_input_names_the_argument(fn, args, name):
    with pytest.raises(ValueError, match=f"^{name}:"):
        fn(*args)
