"""velogauss_ref.motion.coefficients: VG-COEF, w = m(z) P(t) from K motion patterns, masked."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tests.ref.gradcheck import check_grads_fd
from tests.ref.motion.cases import (FD_STEP, RIGID_MASK, TRANSLATION_MASK, affine_matrix, flat_params, random_params,
                                    small_cfg)
from velogauss_ref.motion import coefficients as coef_module
from velogauss.scenes.trajectories import PeriodicFlowMotion, RigidMotion
from velogauss_ref.motion.coefficients import (centred, coefficients, harmonic_velocity_patterns, mixing_weights,
                                              motion_patterns, rigid_velocity_patterns)
from velogauss_ref.nn import mlp, positional_encoding

seeds = st.integers(0, 2**32 - 1)
times = st.sampled_from([0.0, 0.37, 1.0, -2.5, 6.0])
codes = hnp.arrays(np.float64, (6, 3), elements=st.floats(-3, 3))


def _patterns(params, t, cfg):
    """P(t) (K, 12) through the public VG-ENC and VG-MLP, which have their own tests, each written
    about its centre by hand (VG-COEF-CENTRE): translation b - A c."""
    P = mlp(params["time"], positional_encoding(np.array([t]), cfg.n_freqs_t)).reshape(cfg.n_patterns, 12)
    shift = np.stack([affine_matrix(p) @ c for p, c in zip(P, params["centre"])])
    return np.concatenate([P[:, :3] - shift, P[:, 3:]], axis=1)


@pytest.mark.spec("VG-COEF")
@given(seeds, times, codes)
def test_mixture_of_patterns(seed, t, z):
    cfg = small_cfg()
    params = random_params(seed, cfg)
    A, c = params["mix"][0]
    u = z @ A + c
    m = np.exp(u) / np.exp(u).sum(axis=1, keepdims=True)  # |u| < 20: the textbook softmax is exact here
    np.testing.assert_allclose(coefficients(params, t, z, cfg), m @ _patterns(params, t, cfg), rtol=0,
                               atol=1e-12 * (1 + np.abs(_patterns(params, t, cfg)).max()))


@pytest.mark.spec("VG-COEF")
def test_time_network_runs_once_per_time(monkeypatch):
    cfg = small_cfg(n_freqs_t=2)
    params = random_params(1, cfg)
    calls = []

    def counting_mlp(layers, x):
        calls.append((layers is params["time"], np.shape(x)))
        return mlp(layers, x)

    monkeypatch.setattr(coef_module, "mlp", counting_mlp)
    w = coefficients(params, 0.4, np.random.default_rng(1).standard_normal((50, cfg.code_dim)), cfg)
    # One evaluation, on gamma(t) alone (5 values), for all 50 particles.
    assert calls == [(True, (1 + 2 * cfg.n_freqs_t,))]
    assert w.shape == (50, 12)


@pytest.mark.spec("VG-COEF")
@given(seeds, hnp.arrays(np.float64, (8, 3), elements=st.floats(-1e3, 1e3)))
def test_mixing_weights_are_a_distribution(seed, z):
    # Codes up to 1e3 make z A + c reach ~1e3, where exp overflows: the weights must not.
    cfg = small_cfg()
    m = mixing_weights(random_params(seed, cfg), z)
    assert m.shape == (8, cfg.n_patterns)
    assert np.all(m >= 0)
    np.testing.assert_allclose(m.sum(axis=1), 1.0, rtol=0, atol=1e-14)


@pytest.mark.spec("VG-COEF")
@given(seeds, times, codes)
def test_every_row_lies_in_the_patterns_hull(seed, t, z):
    cfg = small_cfg()
    params = random_params(seed, cfg)
    w, P = coefficients(params, t, z, cfg), _patterns(params, t, cfg)
    slack = 1e-12 * (1 + np.abs(P).max())
    assert np.all(w >= P.min(axis=0) - slack) and np.all(w <= P.max(axis=0) + slack)
    # With z-independent mixing (A = 0) all particles share one w.
    same = {**params, "mix": [(np.zeros_like(params["mix"][0][0]), params["mix"][0][1])]}
    w_same = coefficients(same, t, z, cfg)
    np.testing.assert_allclose(w_same, np.broadcast_to(w_same[0], w_same.shape), rtol=0, atol=1e-14)


@pytest.mark.spec("VG-COEF")
@pytest.mark.parametrize("mask", [RIGID_MASK, TRANSLATION_MASK])
def test_mask_zeroes_exactly_the_unselected_columns(mask):
    z = np.random.default_rng(2).standard_normal((7, 3)) * 3
    params = random_params(2, small_cfg())
    w_masked = coefficients(params, 0.8, z, small_cfg(mask=mask))
    w = coefficients(params, 0.8, z, small_cfg())
    assert np.all(w_masked[:, ~mask] == 0.0)
    np.testing.assert_array_equal(w_masked[:, mask], w[:, mask])
    assert np.all(w[:, ~mask] != 0.0)  # the mask, not the parameters, zeroes them


@pytest.mark.spec("VG-COEF", "VG-COEF-RIGID", "VG-COEF-HARM")
@pytest.mark.parametrize("masked", [False, True])
@given(seed=seeds, t=st.floats(-3, 3), z=hnp.arrays(np.float64, (3, 3), elements=st.floats(-2, 2)),
       n_freqs_t=st.integers(0, 2), pattern_form=st.sampled_from(["mlp", "rigid", "harmonic"]))
def test_coefficients_gradient(masked, seed, t, z, n_freqs_t, pattern_form):
    cfg = small_cfg(mask=RIGID_MASK if masked else None, n_freqs_t=n_freqs_t, pattern_form=pattern_form,
                    max_time=0.75)
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, t, z: coefficients(unflatten(theta), t, z, cfg), (theta, t, z), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.spec("VG-COEF-COAST")
@given(seed=seeds, t=st.floats(-3, 3), pattern_form=st.sampled_from(["mlp", "rigid", "harmonic"]))
def test_coasting_patterns_keep_their_value_at_the_window_s_end(seed, t, pattern_form):
    # P(min(t, T)) through each form's own public function (tested above), exactly: inside the
    # window the coasting patterns are VG-COEF's to the bit, past it they stay at T's.
    max_time = 0.6
    coast = small_cfg(pattern_form=pattern_form, max_time=max_time, future="coast")
    params = random_params(seed, coast)
    tau = min(t, max_time)
    expected = motion_patterns(params, tau, dataclasses.replace(coast, future="integrate"))
    np.testing.assert_array_equal(motion_patterns(params, t, coast), expected)


@pytest.mark.spec("VG-COEF-COAST")
@given(seed=seeds, t=st.one_of(st.floats(-3, 0.7), st.floats(0.8, 3)),
       z=hnp.arrays(np.float64, (3, 3), elements=st.floats(-2, 2)),
       pattern_form=st.sampled_from(["mlp", "rigid", "harmonic"]))
def test_coasting_coefficients_gradient(seed, t, z, pattern_form):
    # Probes stay 0.05 from T = 0.75, where dw/dt jumps to 0.
    cfg = small_cfg(pattern_form=pattern_form, max_time=0.75, future="coast")
    theta, unflatten = flat_params(random_params(seed, cfg))
    check_grads_fd(lambda theta, t, z: coefficients(unflatten(theta), t, z, cfg), (theta, t, z), (0, 1, 2),
                   np.random.default_rng(seed), step=FD_STEP)


@pytest.mark.spec("VG-COEF-RIGID")
@pytest.mark.parametrize("max_time", [0.75, 0.4, 1.0])
@pytest.mark.parametrize("gravity, n", [((0.0, 0.0, -8.0), 3), ((0.0, 0.0, 0.0), 2)])
def test_rigid_patterns_are_the_thrown_body_at_every_time(max_time, gravity, n):
    # velogauss.scenes' analytic motion: a constant spin about a centre thrown under gravity
    # (3 knots) or drifting (2). B = the spin and the centre's positions at the knots gives
    # the body's basis coefficients (its own inversion of the affine motion) inside the
    # window and past it, where the polynomial through the knots continues as the body does.
    body = RigidMotion(centre=(0.3, -0.2, 0.1), omega=(1.8, 0.7, 0.4), velocity=(1.0, 0.5, 2.0), gravity=gravity)
    centre = body.centre[None]
    knots = [body.position(centre, t)[0] for t in np.linspace(0.0, max_time, n)]
    B = np.tile(np.concatenate([body.omega, *knots]), (3, 1))
    for t in (0.0, 0.2, max_time, 1.0, 2.5):
        P = rigid_velocity_patterns(B, t, max_time)
        np.testing.assert_allclose(P, np.broadcast_to(body.basis_coefficients(t), P.shape), rtol=0, atol=1e-12)


@pytest.mark.spec("VG-COEF-RIGID")
@given(seed=seeds, t=st.floats(-2, 3), n=st.sampled_from([2, 3]))
def test_rigid_patterns_are_rigid_fields_with_a_constant_spin(seed, t, n):
    # No stretch or shear at any time, and the rotation columns are the spin at every t.
    B = np.random.default_rng(seed).standard_normal((5, 3 + 3 * n))
    P = rigid_velocity_patterns(B, t, 0.75)
    assert np.all(P[:, 6:] == 0.0)
    np.testing.assert_array_equal(P[:, 3:6], B[:, :3])
    still = rigid_velocity_patterns(np.concatenate([np.zeros((5, 3)), B[:, 3:]], axis=1), t, 0.75)
    # Without spin the translation is the centre's velocity: the derivative of the
    # polynomial through the knots, here numpy's fit through them, differentiated.
    nodes = np.linspace(0.0, 0.75, n)
    fits = [np.polyfit(nodes, B[k, 3:].reshape(n, 3), n - 1) for k in range(5)]  # [n powers, 3]
    rate = np.stack([np.polyval(np.polyder(f[:, j]), t) for f in fits for j in range(3)]).reshape(5, 3)
    np.testing.assert_allclose(still[:, :3], rate, rtol=1e-9, atol=1e-9)


@pytest.mark.spec("VG-COEF-HARM")
@pytest.mark.parametrize("generator", [np.diag([0.47, -0.235, -0.235]), [[0.2, 0.0, 0.6], [0.0, -0.4, 0.1],
                                                                        [0.6, 0.1, 0.2]]])
def test_harmonic_patterns_are_the_pulsing_body_at_every_time(generator):
    # velogauss.scenes' analytic periodic flow x - c = expm(sin(w t) L)(x0 - c), off the
    # origin: its velocity w cos(w t) L (x - c) has the coefficients cos(w t) w(0). Patterns
    # with Omega = w, a = c = 0 and b = w(0) give them inside the window and for several
    # periods past it, where no polynomial in t could follow.
    body = PeriodicFlowMotion(centre=(0.3, -0.2, 0.1), generator=generator, omega=3 * np.pi)
    C = np.zeros((3, 4, 12))
    C[1] = body.basis_coefficients(0.0)
    for t in (0.0, 0.1, 0.5, 0.75, 1.0, 2.3):
        P = harmonic_velocity_patterns(C, np.array([body.omega]), t)
        np.testing.assert_allclose(P, np.broadcast_to(body.basis_coefficients(t), P.shape), rtol=0, atol=1e-12)


@pytest.mark.spec("VG-COEF-HARM")
@given(seed=seeds, t=st.floats(-2, 3), omega=st.floats(0.5, 30))
def test_harmonic_patterns_repeat_with_their_period(seed, t, omega):
    # The patterns return to their values after the period 2 pi / Omega, and still
    # oscillators (b = c = 0) are their means a at every time.
    C = np.random.default_rng(seed).standard_normal((3, 4, 12))
    P = harmonic_velocity_patterns(C, np.array([omega]), t)
    later = harmonic_velocity_patterns(C, np.array([omega]), t + 2 * np.pi / omega)
    np.testing.assert_allclose(later, P, rtol=0, atol=1e-9)
    still = np.stack([C[0], np.zeros((4, 12)), np.zeros((4, 12))])
    np.testing.assert_array_equal(harmonic_velocity_patterns(still, np.array([omega]), t), C[0])


@pytest.mark.parametrize(
    "t, z, name",
    [
        (np.nan, np.zeros((3, 3)), "t"),
        (np.zeros(2), np.zeros((3, 3)), "t"),
        (0.5, np.zeros((3, 4)), "z"),
        (0.5, np.full((3, 3), np.inf), "z"),
    ],
)
def test_bad_input_names_the_argument(t, z, name):
    cfg = small_cfg()
    with pytest.raises(ValueError, match=f"^{name}:"):
        coefficients(random_params(0, cfg), t, z, cfg)


@pytest.mark.spec("VG-COEF-CENTRE")
@given(seed=seeds, x=hnp.arrays(np.float64, (5, 3), elements=st.floats(-3, 3)))
def test_centred_patterns_are_each_pattern_about_its_centre(seed, x):
    # Oracle: pattern k's field A(P_k) (x - c_k) + b(P_k), with A written out by hand.
    rng = np.random.default_rng(seed)
    P, centres = rng.standard_normal((4, 12)), 2 * rng.standard_normal((4, 3))
    world = centred(P, centres)
    np.testing.assert_array_equal(world[:, 3:], P[:, 3:])  # only the translation changes
    for k in range(4):
        expected = (x - centres[k]) @ affine_matrix(P[k]).T + P[k, :3]
        got = x @ affine_matrix(world[k]).T + world[k, :3]
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * (1 + np.abs(expected).max()))
    np.testing.assert_array_equal(centred(P, None), P)


@pytest.mark.spec("VG-COEF-CENTRE")
def test_a_spin_about_its_centre_needs_no_translation():
    # A body spinning at omega about c far from the origin: about c the pattern is the spin alone;
    # in the world's frame it carries b = -omega x c, the coupling the centres remove.
    omega, c = np.array([0.3, -1.2, 2.0]), np.array([5.0, -4.0, 3.0])
    P = np.concatenate([np.zeros(3), omega, np.zeros(6)])[None]
    np.testing.assert_allclose(centred(P, c[None])[0, :3], -np.cross(omega, c), rtol=0, atol=1e-12)


@pytest.mark.spec("VG-COEF-CENTRE")
@pytest.mark.parametrize("pattern_form", ["mlp", "harmonic"])
def test_motion_patterns_are_written_about_the_centres(pattern_form):
    # Moving every centre by d moves each pattern's field with it: Phi(x + d) P'(t) = Phi(x) P(t).
    cfg = small_cfg(pattern_form=pattern_form)
    params = random_params(3, cfg)
    d = np.array([0.7, -0.4, 1.1])
    moved = {**params, "centre": params["centre"] + d}
    x = np.random.default_rng(0).standard_normal((6, 3))
    for k, (p, q) in enumerate(zip(motion_patterns(params, 0.4, cfg), motion_patterns(moved, 0.4, cfg))):
        np.testing.assert_allclose((x + d) @ affine_matrix(q).T + q[:3], x @ affine_matrix(p).T + p[:3],
                                   rtol=0, atol=1e-12)


def test_bad_centres_name_the_argument():
    with pytest.raises(ValueError, match="centres"):
        centred(np.zeros((4, 12)), np.zeros((3, 3)))
