"""Tests of velogauss/model/profile.py: a scene's effects select what the motion model builds."""

import dataclasses
import inspect

import numpy as np
import pytest

from velogauss.config import ModelConfig
from velogauss.model.build import profile_from_dict
from velogauss.model.profile import resolve_profile
from velogauss.scenes import SCENES
from velogauss.scenes.motions import LinearFlowMotion, PeriodicFlowMotion, RigidMotion, StaticMotion

T, R, S, H = range(0, 3), range(3, 6), range(6, 9), range(9, 12)


def _cols(*groups):
    return tuple(c in {i for g in groups for i in g} for c in range(12))


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
    p = resolve_profile(effects, True, acceleration="auto")
    assert p.moving and p.mask == mask and p.acceleration == acc and p.acc_mask == acc_mask
    assert p.acc_form == form and p.divergence


def test_acceleration_form_can_be_chosen():
    # The default is the polynomial; on a falling body it keeps the translation-only columns.
    falling = resolve_profile(("translation", "gravity"), True)
    assert falling.acc_form == "poly" and falling.acc_mask == _cols(T)
    assert resolve_profile(("rotation",), True, acceleration="poly").acc_form == "poly"
    assert resolve_profile(("rotation", "gravity"), True, acceleration="rigid").acc_form == "rigid"
    # No acceleration at all: nothing to choose.
    assert resolve_profile(("translation",), True, acceleration="rigid").acc_form == "poly"


@pytest.mark.parametrize("effects", [("stretch",), ("rotation", "shear")])
def test_rigid_acceleration_refuses_a_deforming_scene(effects):
    with pytest.raises(ValueError, match=r"^model\.acceleration: 'rigid' cannot follow"):
        resolve_profile(effects, True, acceleration="rigid")


@pytest.mark.parametrize("effects, auto", [
    (("translation", "rotation", "gravity"), "rigid"), (("translation",), "rigid"), (("rotation", "static"), "rigid"),
    (("stretch",), "mlp"), (("translation", "shear"), "mlp"), (("static",), "mlp"),
])
def test_pattern_form_auto_is_rigid_exactly_for_rigid_motion(effects, auto):
    assert resolve_profile(effects, True, patterns="auto").pattern_form == auto
    assert resolve_profile(effects, True).pattern_form == auto  # the default, the config's
    assert resolve_profile(effects, True, patterns="mlp").pattern_form == "mlp"
    # The centre accelerates (a third knot) only under gravity.
    assert resolve_profile(effects, True, patterns="auto").rigid_knots == (3 if "gravity" in effects else 2)


@pytest.mark.parametrize("effects", [("stretch", "oscillation"), ("rotation", "oscillation")])
def test_oscillation_brings_harmonic_patterns_and_their_acceleration(effects):
    # "auto": a declared oscillation takes VG-COEF-HARM before the rigid form, and its
    # acceleration is VG-ACC-HARM whatever model.acceleration says (it needs the frequencies).
    for acceleration in ("poly", "auto"):
        p = resolve_profile(effects, True, acceleration=acceleration, patterns="auto")
        assert (p.pattern_form, p.acc_form, p.acceleration) == ("harmonic", "harmonic", True)
    assert resolve_profile(effects, True, patterns="mlp").pattern_form == "mlp"
    # Oscillation alone moves nothing: it is a statement about time, not a basis column.
    assert not resolve_profile(("oscillation",), True, patterns="auto").moving


@pytest.mark.parametrize("effects", [("stretch",), ("rotation", "shear")])
def test_rigid_patterns_refuse_a_deforming_scene(effects):
    with pytest.raises(ValueError, match=r"^model\.patterns: 'rigid' cannot follow"):
        resolve_profile(effects, True, patterns="rigid")


def test_the_keyword_defaults_are_the_configs():
    defaults = {k: v.default for k, v in inspect.signature(resolve_profile).parameters.items()}
    model = ModelConfig()
    assert [defaults[k] for k in ("acceleration", "patterns", "rasterize_mode")] == [
        model.acceleration, model.patterns, model.rasterize_mode]


def test_a_profile_reads_back_as_it_was_saved():
    # Checkpoints store dataclasses.asdict(profile); every field is needed to read it back.
    profile = resolve_profile(("rotation",), True, acceleration="rigid", patterns="rigid", rasterize_mode="classic")
    saved = dataclasses.asdict(profile)
    assert profile_from_dict(saved) == profile
    del saved["rasterize_mode"]
    with pytest.raises(TypeError, match="rasterize_mode"):
        profile_from_dict(saved)


@pytest.mark.parametrize("mode", ["classic", "antialiased"])
def test_the_profile_carries_the_rasterize_mode(mode):
    assert resolve_profile(("stretch",), True, rasterize_mode=mode).rasterize_mode == mode


def test_rigid_is_six_columns_affine_is_twelve():
    assert resolve_profile(("translation", "rotation"), True).n_columns == 6
    assert resolve_profile(("translation", "rotation", "stretch", "shear"), True).n_columns == 12


def test_static_scene_builds_no_motion():
    p = resolve_profile(("static",), True)
    assert not p.moving and p.n_columns == 0 and not p.acceleration and not p.divergence


def test_divergence_only_for_incompressible_motion():
    assert not resolve_profile(("stretch",), False).divergence
    assert resolve_profile(("stretch",), True).divergence


def test_auto_reads_the_scene_then_falls_back_to_everything():
    p = resolve_profile("auto", "auto", {"effects": ["rotation"], "incompressible": False})
    assert p.effects == ("rotation",) and not p.divergence
    q = resolve_profile("auto", "auto", None)
    assert q.n_columns == 12 and q.divergence and q.acceleration
    # ... every effect but oscillation, an assumption about time only a declaration makes.
    assert "oscillation" not in q.effects and "static" in q.effects


@pytest.mark.parametrize("name", sorted(SCENES))
def test_catalog_motion_lies_in_the_selected_columns(name, rng):
    # The true velocity of every body must be representable with the profile's columns:
    # fit the 12 coefficients of v(x) = A x + b by least squares on random points, then
    # check the unselected columns are (numerically) unused.
    from velogauss_ref.motion.basis import basis_matrix

    scene = SCENES[name]()
    p = resolve_profile(scene.effects, scene.incompressible)
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
