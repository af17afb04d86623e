"""Tests of velogauss/model/spec.py: a scene's effects and the config resolve what the motion model builds."""

import dataclasses

import numpy as np
import pytest

from velogauss.config import ModelConfig, load_config
from velogauss.model import build_model, model_from_state, scene_spec
from velogauss.model.spec import resolve_motion_spec
from velogauss_core.motion import EFFECTS, UNDECLARED_EFFECTS, MotionSpec, spec_from_dict
from velogauss.scenes import SCENES
from velogauss.scenes.trajectories import LinearFlowMotion, PeriodicFlowMotion, RigidMotion, StaticMotion

T, R, S, H = range(0, 3), range(3, 6), range(6, 9), range(9, 12)


def _cols(*groups):
    return tuple(c in {i for g in groups for i in g} for c in range(12))


def resolve(effects, incompressible, metadata=None, **keys):
    """The `MotionSpec` of the default `[model]` section with these keys, for a scene with `metadata`."""
    effects = effects if effects in ("auto", "declared") else tuple(effects)
    return resolve_motion_spec(ModelConfig(effects=effects, incompressible=incompressible, **keys), metadata, 1.0)


@pytest.mark.parametrize("effects, mask, acc, acc_mask, form", [
    (("translation",), _cols(T), False, _cols(), "poly"),
    (("translation", "gravity"), _cols(T), True, _cols(T, R, S, H), "rigid"),
    (("gravity",), _cols(T), True, _cols(T, R, S, H), "rigid"),
    (("rotation",), _cols(T, R), True, _cols(T, R, S, H), "rigid"),
    (("translation", "rotation", "gravity"), _cols(T, R), True, _cols(T, R, S, H), "rigid"),
    (("stretch",), _cols(T, S), True, _cols(T, R, S, H), "poly"),
    (("shear",), _cols(T, H), True, _cols(T, R, S, H), "poly"),
    (("translation", "rotation", "stretch", "shear"), _cols(T, R, S, H), True, _cols(T, R, S, H), "poly"),
])
def test_columns_and_acceleration(effects, mask, acc, acc_mask, form):
    p = resolve(effects, True, acceleration="auto")
    assert p.moving and p.mask == mask and p.acceleration == acc and p.acc_mask == acc_mask
    assert p.acc_form == form and p.divergence


def test_acceleration_form_can_be_chosen():
    # The default is the polynomial; on a falling body it keeps the translation-only columns.
    falling = resolve(("translation", "gravity"), True)
    assert falling.acc_form == "poly" and falling.acc_mask == _cols(T)
    assert resolve(("rotation",), True, acceleration="poly").acc_form == "poly"
    assert resolve(("rotation", "gravity"), True, acceleration="rigid").acc_form == "rigid"
    # No acceleration at all: nothing to choose.
    assert resolve(("translation",), True, acceleration="rigid").acc_form == "poly"


@pytest.mark.parametrize("effects", [("stretch",), ("rotation", "shear")])
def test_rigid_acceleration_refuses_a_deforming_scene(effects):
    with pytest.raises(ValueError, match=r"^model\.acceleration: 'rigid' cannot follow"):
        resolve(effects, True, acceleration="rigid")


@pytest.mark.parametrize("effects, rigid", [
    (("translation", "rotation", "gravity"), True), (("translation",), True), (("rotation", "static"), True),
    (("stretch",), False), (("translation", "shear"), False), (("static",), False),
])
def test_pattern_form_auto_is_the_time_network_and_rigid_is_asked_for(effects, rigid):
    # "auto" is chosen from the data by the backtest before a run (velogauss.train.backtest);
    # one that reaches the spec unchosen is the time network, whatever the effects, rigid or not.
    assert resolve(effects, True, patterns="auto").pattern_form == "mlp"
    assert resolve(effects, True).pattern_form == "mlp"  # the default, the config's
    # ... and whatever the scene declares: "declared" effects do not bring back a form either.
    assert resolve("declared", True, {"effects": list(effects)}).pattern_form == "mlp"
    assert resolve(effects, True, patterns="mlp").pattern_form == "mlp"
    if rigid:  # rigid motion takes the rigid form when asked for
        p = resolve(effects, True, patterns="rigid")
        assert p.pattern_form == "rigid" and p.moving
        # The centre accelerates (a third knot) only under gravity.
        assert p.rigid_knots == (3 if "gravity" in effects else 2)
    assert resolve(effects, True, patterns="auto").rigid_knots == (3 if "gravity" in effects else 2)


@pytest.mark.parametrize("effects", [("stretch", "oscillation"), ("rotation", "oscillation")])
def test_oscillation_brings_harmonic_patterns_and_their_acceleration(effects):
    # Harmonic patterns (VG-COEF-HARM) take VG-ACC-HARM as their acceleration whatever
    # model.acceleration says (it needs the frequencies).
    for acceleration in ("poly", "auto"):
        p = resolve(effects, True, acceleration=acceleration, patterns="harmonic")
        assert (p.pattern_form, p.acc_form, p.acceleration) == ("harmonic", "harmonic", True)
        # A declared oscillation no longer picks them by itself: "auto" is the time network.
        q = resolve(effects, True, acceleration=acceleration, patterns="auto")
        assert q.pattern_form == "mlp" and q.acc_form != "harmonic"
    assert resolve(effects, True, patterns="mlp").pattern_form == "mlp"
    # Oscillation alone moves nothing: it is a statement about time, not a basis column.
    assert not resolve(("oscillation",), True, patterns="harmonic").moving
    assert not resolve(("oscillation",), True, patterns="auto").moving


@pytest.mark.parametrize("effects", [("stretch",), ("rotation", "shear")])
def test_rigid_patterns_refuse_a_deforming_scene(effects):
    with pytest.raises(ValueError, match=r"^model\.patterns: 'rigid' cannot follow"):
        resolve(effects, True, patterns="rigid")


def test_the_specs_defaults_are_the_default_configs_plan():
    # A MotionSpec built directly (the pure functions' tests) means the default config's model
    # for a scene that declares nothing, over the whole window; masks None are every column.
    resolved = resolve_motion_spec(ModelConfig(), None, 1.0)
    assert dataclasses.replace(resolved, mask=None, acc_mask=None) == MotionSpec()
    assert resolved.mask == resolved.acc_mask == (True,) * 12


def test_a_spec_reads_back_as_it_was_saved():
    # Checkpoints store dataclasses.asdict(spec); every field is needed to read it back.
    spec = resolve(("rotation",), True, acceleration="rigid", patterns="rigid")
    saved = dataclasses.asdict(spec)
    assert spec_from_dict(saved) == spec
    with pytest.raises(ValueError, match="^effects: missing from the saved MotionSpec"):
        spec_from_dict({k: v for k, v in saved.items() if k != "effects"})
    with pytest.raises(ValueError, match="^profile: not a field of the saved MotionSpec"):
        spec_from_dict({**saved, "profile": None})


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_a_model_renders_in_its_configs_mode(mode):
    cfg = load_config(None, [f"model.rasterize_mode={mode}", "model.n_patterns=2", "model.hidden=4"])
    spec = scene_spec(cfg, {"effects": ["stretch"]})
    model = build_model(cfg, spec, np.zeros((4, 3)), None, np.random.default_rng(0))
    assert model.rasterize_mode == mode
    assert model_from_state(cfg, spec, model.state_dict()).rasterize_mode == mode


def test_rigid_is_six_columns_affine_is_twelve():
    assert resolve(("translation", "rotation"), True).mask.count(True) == 6
    assert resolve(("translation", "rotation", "stretch", "shear"), True).mask.count(True) == 12


def test_static_scene_builds_no_motion():
    p = resolve(("static",), True)
    assert not p.moving and not any(p.mask) and not p.acceleration and not p.divergence


def test_divergence_only_for_incompressible_motion():
    assert not resolve(("stretch",), False).divergence
    assert resolve(("stretch",), True).divergence


def test_auto_ignores_the_scene_and_declared_reads_it():
    scene = {"effects": ["rotation"], "incompressible": False}
    # "auto" reads nothing the scene declares: every effect but oscillation, incompressible.
    for metadata in (scene, None):
        p = resolve("auto", "auto", metadata)
        assert p.effects == tuple(e for e in EFFECTS if e in UNDECLARED_EFFECTS)
        assert all(p.mask) and p.divergence and p.acceleration
        # ... every effect but oscillation, an assumption about time only a declaration makes.
        assert "oscillation" not in p.effects and "static" in p.effects
    # "declared" takes scene.json's declaration, the optional prior ...
    q = resolve("declared", "declared", scene)
    assert q.effects == ("rotation",) and not q.divergence
    assert q.mask == _cols(T, R)
    # ... each key on its own ...
    assert resolve("declared", "auto", scene).divergence
    assert resolve("auto", "declared", scene).effects == p.effects
    assert not resolve(("rotation",), "declared", scene).divergence
    # ... and falls back to everything when the scene declares nothing.
    r = resolve("declared", "declared", None)
    assert r.effects == p.effects and r.divergence and all(r.mask)
    assert resolve("declared", "declared", {}).effects == p.effects


@pytest.mark.parametrize("name", sorted(SCENES))
def test_catalog_motion_lies_in_the_selected_columns(name, rng):
    # The true velocity of every body must be representable with the spec's columns:
    # fit the 12 coefficients of v(x) = A x + b by least squares on random points, then
    # check the unselected columns are (numerically) unused.
    from velogauss_ref.motion.basis import basis_matrix

    scene = SCENES[name]()
    p = resolve(scene.effects, scene.incompressible)
    for body in scene.bodies:
        if isinstance(body.motion, StaticMotion):
            continue
        assert isinstance(body.motion, (RigidMotion, LinearFlowMotion, PeriodicFlowMotion))
        for t in (0.0, 0.5, 0.9):
            x = rng.uniform(-1, 1, (40, 3))
            v = body.motion.velocity(x, t)
            Phi = basis_matrix(x)[:, :, list(np.flatnonzero(p.mask))]  # (40, 3, k)
            w, *_ = np.linalg.lstsq(Phi.reshape(-1, Phi.shape[-1]), v.reshape(-1), rcond=None)
            residual = Phi.reshape(-1, Phi.shape[-1]) @ w - v.reshape(-1)
            # Exactly representable: only float64 rounding of the least-squares solve remains.
            assert np.abs(residual).max() < 1e-9 * max(1.0, np.abs(v).max()), (name, body.name, t)
