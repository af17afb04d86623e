"""velogauss.model: the resolved MotionSpec, the parameter module and the pure motion functions."""

import dataclasses

import numpy as np
import pytest
import torch

from velogauss.config import ModelConfig
from velogauss.model.velogauss_model import VeloGaussModel
from velogauss.model.gaussians import Gaussians
from velogauss.model.motion import MotionParameters, gaussians_at, motion_residuals, particle_velocity, velocity_at
from velogauss.model.spec import ABLATION_SWITCHES, resolve_motion_spec
from velogauss_core.motion import ABLATIONS

# Scenes as `[model]` keys, with the time network's patterns (VG-COEF) throughout, whatever the effects.
RIGID = dict(effects=("translation", "rotation"), incompressible=False, patterns="mlp")
INCOMPRESSIBLE = dict(effects=("translation", "rotation"), incompressible=True, patterns="mlp")
GRAVITY = dict(effects=("translation", "gravity"), incompressible=False, patterns="mlp")
STATIC = dict(effects=("static",), incompressible=False, patterns="mlp")
# Uniform translation: Dv/Dt = 0, so no acceleration polynomial (velogauss.model.spec).
DRIFT = dict(effects=("translation",), incompressible=False, patterns="mlp")
SMALL = dict(n_freqs_x=1, n_freqs_adf_x=1, n_freqs_adf_t=1, code_dim=3, n_patterns=4, hidden=8, depth=1)


def _spec(ablation="full", scene=RIGID, **overrides):
    return resolve_motion_spec(ModelConfig(ablation=ablation, **{**scene, **SMALL, **overrides}), None, 0.75)


def _canonical(n=16, seed=0):
    rng = np.random.default_rng(seed)
    q = torch.tensor(rng.standard_normal((n, 4)), dtype=torch.float32)
    return (torch.tensor(rng.uniform(-1, 1, (n, 3)), dtype=torch.float32), q / q.norm(dim=1, keepdim=True),
            torch.tensor(rng.uniform(0.05, 0.2, (n, 3)), dtype=torch.float32))


def _assert_states_close(state, expected):
    """(means, quats, scales, base) equal up to float32 rounding of a few O(1) operations."""
    for name, a, b in zip(("means", "quats", "scales", "base"), state, expected):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-6, msg=lambda m, name=name: f"{name}: {m}")


# The paper's ablation table (velogauss.model.spec): velocity, ADF, physics losses.
@pytest.mark.parametrize("ablation, velocity, adf, physics", [
    ("full", "affine", True, True), ("no-pds", "mlp", True, True), ("no-adf", "affine", False, True),
    ("no-gpc", "affine", True, False), ("deform-only", None, True, False)])
def test_each_ablation_resolves_to_its_row_of_the_table(ablation, velocity, adf, physics):
    spec = _spec(ablation, INCOMPRESSIBLE)
    assert (spec.scheme, spec.moving, spec.velocity, spec.adf, spec.physics_loss) == (
        "integrate", True, velocity, adf, physics)
    assert spec.adf_loss == (adf and velocity is not None)
    assert spec.divergence == physics  # the scene is incompressible: on wherever GPC is
    # deform-only is DefGS-style: its ADF sees every t; the others hold it at max_time.
    assert spec.adf_clamp_time == (None if ablation == "deform-only" else 0.75)
    assert spec.mask == (True,) * 6 + (False,) * 6 and spec.code_dim == SMALL["code_dim"]


def test_every_ablation_has_exactly_one_row():
    assert tuple(ABLATION_SWITCHES) == ABLATIONS


def test_a_static_scene_resolves_to_no_motion_and_no_losses():
    for ablation in ABLATIONS:
        spec = _spec(ablation, STATIC)
        assert not (spec.moving or spec.velocity or spec.adf or spec.adf_loss or spec.physics_loss
                    or spec.divergence or spec.acceleration), ablation
        with pytest.raises(ValueError, match="^spec: "):
            MotionParameters(spec, np.random.default_rng(0))


def test_parameters_follow_the_spec():
    full = MotionParameters(_spec("full", GRAVITY), np.random.default_rng(0))
    assert {"code", "mix", "time", "adf", "acc"} <= set(dict(full.named_children()) | dict(full.named_parameters()))
    assert set(full.params()) == {"code", "mix", "time", "adf", "acc", "centre"}
    # The patterns' centres are data, not trained: a buffer, which the state (checkpoints) holds.
    assert "centre" not in dict(full.named_parameters()) and "centre" in full.state_dict()
    no_adf = MotionParameters(_spec("no-adf", DRIFT), np.random.default_rng(0))
    assert not hasattr(no_adf, "adf") and not hasattr(no_adf, "acc")
    params = no_adf.params()
    assert set(params) == {"code", "mix", "time", "acc", "centre"} and not params["acc"].any()  # Q = 0, not a parameter
    no_pds = MotionParameters(_spec("no-pds", RIGID), np.random.default_rng(0))
    assert hasattr(no_pds, "velocity_mlp") and not hasattr(no_pds, "time")


def test_a_fresh_model_is_the_still_canonical_scene():
    # Zero heads (time network, velocity MLP, ADF): every ablation starts where it stands.
    x0, q0, s0 = _canonical()
    for ablation in ABLATIONS:
        spec = _spec(ablation)
        params = MotionParameters(spec, np.random.default_rng(1)).params()
        for t in (0.0, 0.4, 1.3):
            _assert_states_close(gaussians_at(params, spec, x0, q0, s0, t), (x0, q0, s0, x0))


def test_skipping_a_zero_adf_changes_nothing():
    # What training does before adf_start (spec.without_adf) is exact while the ADF head is zero.
    x0, q0, s0 = _canonical()
    spec = _spec("full")
    motion = MotionParameters(spec, np.random.default_rng(2))
    with torch.no_grad():
        motion.time[-1].normal_(generator=torch.Generator().manual_seed(3))
    params = motion.params()
    _assert_states_close(gaussians_at(params, spec, x0, q0, s0, 0.6),
                         gaussians_at(params, spec.without_adf(), x0, q0, s0, 0.6))


def test_mlp_velocity_moves_positions_only():
    # A constant MLP velocity (zero weights, bias 0.5 along x): x = x0 + 0.5 t, q and s canonical.
    x0, q0, s0 = _canonical()
    spec = _spec("no-pds")
    motion = MotionParameters(spec, np.random.default_rng(4))
    with torch.no_grad():
        motion.velocity_mlp[-1].copy_(torch.tensor([0.5, 0.0, 0.0]))
        motion.acc.zero_()  # no acceleration, whatever the form (a rigid one starts with a small spin)
    params = motion.params()
    x, q, s, base = gaussians_at(params, spec.without_adf(), x0, q0, s0, 0.8)
    torch.testing.assert_close(x, x0 + torch.tensor([0.4, 0.0, 0.0]), rtol=0, atol=1e-6)
    assert torch.equal(q, q0) and torch.equal(s, s0) and torch.equal(x, base)
    torch.testing.assert_close(velocity_at(params, spec, x0, 0.3), torch.tensor([0.5, 0.0, 0.0]).expand(16, 3))
    r, div = motion_residuals(params, spec, x0, 0.3)  # constant v, no acceleration: r = 0, div = 0
    assert div is None and torch.allclose(r, torch.zeros_like(r), atol=1e-6)


@pytest.mark.parametrize("future, shift_at_09", [("integrate", 0.45), ("hold", 0.375)])
def test_a_held_future_keeps_the_state_at_the_window_end(future, shift_at_09):
    # The constant MLP velocity above (0.5 along x), window end 0.75: integrating gives x0 + 0.5 t;
    # holding stops at x0 + 0.5 * 0.75 = 0.375 with zero velocity past the window, nothing inside it.
    x0, q0, s0 = _canonical()
    spec = _spec("no-pds", future=future)
    assert spec.future == future
    motion = MotionParameters(spec, np.random.default_rng(4))
    with torch.no_grad():
        motion.velocity_mlp[-1].copy_(torch.tensor([0.5, 0.0, 0.0]))
        motion.acc.zero_()
    params = motion.params()
    inside = gaussians_at(params, spec.without_adf(), x0, q0, s0, 0.5)[0]
    torch.testing.assert_close(inside, x0 + torch.tensor([0.25, 0.0, 0.0]), rtol=0, atol=1e-6)
    past = gaussians_at(params, spec.without_adf(), x0, q0, s0, 0.9)[0]
    torch.testing.assert_close(past, x0 + torch.tensor([shift_at_09, 0.0, 0.0]), rtol=0, atol=1e-6)
    speed = 0.0 if future == "hold" else 0.5
    torch.testing.assert_close(velocity_at(params, spec, x0, 0.9), torch.tensor([speed, 0.0, 0.0]).expand(16, 3))
    torch.testing.assert_close(velocity_at(params, spec, x0, 0.75), torch.tensor([0.5, 0.0, 0.0]).expand(16, 3))


def test_a_held_affine_model_answers_with_its_window_end_past_it():
    x0, q0, s0 = _canonical()
    spec = _spec("full", future="hold")
    motion = MotionParameters(spec, np.random.default_rng(2))
    with torch.no_grad():
        motion.time[-1].normal_(generator=torch.Generator().manual_seed(3))
        motion.adf[-1].normal_(generator=torch.Generator().manual_seed(5))
    params = motion.params()
    end = gaussians_at(params, spec, x0, q0, s0, 0.75)
    for t in (0.8, 1.0, 1.4):
        for a, b in zip(gaussians_at(params, spec, x0, q0, s0, t), end):
            assert torch.equal(a, b)
        assert torch.equal(velocity_at(params, spec, end[0], t), torch.zeros_like(x0))
        assert torch.equal(particle_velocity(params, spec, x0, end[0], t), torch.zeros_like(x0))
    # Integrating, the same parameters move on past the window.
    free = dataclasses.replace(spec, future="integrate")
    assert not torch.allclose(gaussians_at(params, free, x0, q0, s0, 1.0)[0], end[0])
    assert velocity_at(params, free, end[0], 1.0).abs().max() > 0
    with pytest.raises(ValueError, match="future: expected one of"):
        dataclasses.replace(spec, future="freeze")


def test_model_rejects_motion_that_does_not_match_its_spec():
    x0, _, _ = _canonical()
    gaussians = Gaussians.from_points(x0.numpy(), None, 0, 0.1)
    with pytest.raises(ValueError, match="^motion: "):
        VeloGaussModel(gaussians, None, _spec("full"), "antialiased")
    static = VeloGaussModel(gaussians, None, _spec("full", STATIC), "antialiased")
    means, quats, _, base = static.state_at(0.7)
    assert torch.equal(means, gaussians.means) and torch.equal(base, gaussians.means)
    assert torch.equal(static.velocity_at(x0, 0.2), torch.zeros_like(x0))


@pytest.mark.parametrize("t", [float("nan"), float("inf"), torch.tensor(float("nan")), torch.zeros(2), "0.5"])
def test_model_refuses_a_bad_time_where_it_enters(t):
    # The model is a door (spec/conventions.md, "Bad input"): finiteness is checked here, once,
    # and the fast functions inside check shapes only. A static model refuses it too.
    x0, _, _ = _canonical()
    gaussians = Gaussians.from_points(x0.numpy(), None, 0, 0.1)
    spec = _spec("full")
    for model in (VeloGaussModel(gaussians, MotionParameters(spec, np.random.default_rng(0)), spec, "antialiased"),
                  VeloGaussModel(gaussians, None, _spec("full", STATIC), "antialiased")):
        for call in (model.state_at, model.render_inputs_at, model.tracked_positions,
                     lambda t: model.velocity_at(x0, t), lambda t: model.particle_velocity(x0, x0, t)):
            with pytest.raises(ValueError, match="^t:"):
                call(t)


def test_model_refuses_bad_points_where_they_enter():
    x0, _, _ = _canonical()
    spec = _spec("full")
    model = VeloGaussModel(Gaussians.from_points(x0.numpy(), None, 0, 0.1),
                           MotionParameters(spec, np.random.default_rng(0)), spec, "antialiased")
    poisoned = x0.clone()
    poisoned[3, 1] = float("nan")
    with pytest.raises(ValueError, match=r"^x: contains 1 non-finite"):
        model.velocity_at(poisoned, 0.2)
    with pytest.raises(ValueError, match="^x: expected shape"):
        model.velocity_at(x0[:, :2], 0.2)
    with pytest.raises(ValueError, match=r"^x0: contains 1 non-finite"):
        model.particle_velocity(poisoned, x0, 0.2)
    with pytest.raises(ValueError, match=r"^x: contains 1 non-finite"):
        model.particle_velocity(x0, poisoned, 0.2)
    with pytest.raises(ValueError, match="^x: expected shape"):
        model.particle_velocity(x0, x0[:5], 0.2)
    assert torch.isfinite(model.velocity_at(x0, torch.tensor(0.2))).all()  # a finite 0-d tensor time passes


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_the_model_renders_in_its_rasterize_mode(mode):
    # The mode travels with the Gaussians (render_inputs_at's dict), so every caller of
    # render_gaussians (training, eval, the viewer) renders as the model was trained.
    from velogauss.data.cameras import Camera, look_at
    from velogauss_fast.raster import rasterize

    x0, _, _ = _canonical()
    gaussians = Gaussians.from_points(0.3 * x0.numpy(), None, 0, 0.5)
    model = VeloGaussModel(gaussians, None, _spec("full", STATIC), rasterize_mode=mode)
    camera = Camera(look_at((0.0, -3.0, 0.0), (0.0, 0.0, 0.0)), np.array([[20.0, 0, 8], [0, 20.0, 8], [0, 0, 1]]), 16, 16)
    g = model.render_inputs_at(0.0)
    assert g["rasterize_mode"] == mode
    image, _, _ = model.render(camera, 0.0, torch.ones(3))
    args = [g[k] for k in ("means", "quats", "scales", "opacities", "colors")]
    cam = [torch.tensor(camera.viewmat, dtype=torch.float32), torch.tensor(camera.K, dtype=torch.float32)]
    for other in ("classic", "antialiased"):
        expected, _, _ = rasterize(*args, *cam, 16, 16, torch.ones(3), g["sh_degree"], mode=other)
        assert torch.equal(image, expected) == (other == mode)


def test_model_refuses_an_unknown_rasterize_mode():
    x0, _, _ = _canonical()
    with pytest.raises(ValueError, match="^mode: "):
        VeloGaussModel(Gaussians.from_points(x0.numpy(), None, 0, 0.1), None, _spec("full", STATIC),
                       rasterize_mode="mip")
