"""Tests of velogauss/config.py: defaults, TOML files, overrides, and bad values named."""

import dataclasses

import pytest

from velogauss.config import (Config, ModelConfig, describe, load_config, resolve_from_run, resolve_schedule,
                              resolve_transport, to_toml)
from velogauss_core.motion import MotionSpec, NetworkSizes


def test_defaults_without_file_or_overrides():
    cfg = load_config()
    assert cfg == Config()
    assert cfg.data.max_time == 0.75
    assert cfg.model.integrator == "rk2" and cfg.model.n_patterns == 32


def test_file_then_overrides_win(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text('[train]\niterations = 50\nseed = 3\n[model]\neffects = ["rotation"]\n')
    cfg = load_config(path, ["train.iterations=70", "data.background=[0, 0, 0]", 'model.ablation="no-adf"'])
    assert cfg.train.iterations == 70  # override beats the file
    assert cfg.train.seed == 3  # the file beats the default
    assert cfg.model.effects == ("rotation",)
    assert cfg.data.background == (0, 0, 0)
    assert cfg.model.ablation == "no-adf"


def _schedule(cfg):
    t, p, d = cfg.train, cfg.physics, cfg.densify
    return (t.warmup, t.curriculum, p.ramp, d.start, d.until, d.every, d.opacity_reset_every, d.static_every)


def test_default_schedule_is_the_measured_one_at_3000_iterations():
    assert _schedule(load_config()) == ("auto",) * 8  # resolved only when a run starts
    assert _schedule(resolve_schedule(load_config(None, ["train.iterations=3000"]))) == (
        200, 1200, 1200, 200, 2000, 100, 1000, 500)
    with pytest.raises(ValueError, match='train.iterations is "auto"'):
        resolve_schedule(load_config())


def test_auto_schedule_scales_with_iterations():
    assert _schedule(resolve_schedule(load_config(None, ["train.iterations=1500"]))) == (
        100, 600, 600, 100, 1000, 50, 500, 250)
    assert _schedule(resolve_schedule(load_config(None, ["train.iterations=6000"]))) == (
        400, 2400, 2400, 400, 4000, 200, 2000, 1000)
    # Intervals stay at least one iteration; spans may round to 0.
    assert _schedule(resolve_schedule(load_config(None, ["train.iterations=3"]))) == (0, 1, 1, 0, 2, 1, 1, 1)


def test_a_schedule_key_set_to_a_number_is_kept():
    cfg = resolve_schedule(load_config(None, ["train.iterations=1500", "train.warmup=7", "densify.every=300"]))
    assert _schedule(cfg) == (7, 600, 600, 100, 1000, 300, 500, 250)


def test_a_resumed_run_keeps_its_schedule():
    saved = resolve_schedule(load_config(None, ["train.iterations=1500"]))
    grown = load_config(None, ["train.iterations=6000", "densify.every=50"])
    cfg = resolve_schedule(grown, saved)
    assert cfg.train.iterations == 6000
    assert _schedule(cfg) == (100, 600, 600, 100, 1000, 50, 500, 250)


@pytest.mark.parametrize("patterns, weight", [("harmonic", 0.0), ("rigid", 1e-3), ("mlp", 1e-3)])
def test_auto_transport_weight_is_off_only_with_oscillating_patterns(patterns, weight):
    assert load_config().physics.lambda_transport == "auto"
    assert resolve_transport(load_config(), patterns).physics.lambda_transport == weight


def test_a_transport_weight_set_to_a_number_is_kept():
    cfg = load_config(None, ["physics.lambda_transport=1e-3"])
    assert resolve_transport(cfg, "harmonic").physics.lambda_transport == 1e-3
    # A resumed run keeps the weight it started with, whatever the profile says now.
    saved = resolve_transport(load_config(), "rigid")
    assert resolve_transport(load_config(), "harmonic", saved).physics.lambda_transport == 1e-3


def test_an_existing_run_gives_its_numbers_to_every_auto_key():
    saved = resolve_transport(resolve_schedule(load_config(None, ["train.iterations=1500"])), "harmonic")
    cfg = resolve_from_run(load_config(None, ["train.iterations=1500"]), saved)
    assert cfg == saved and cfg.physics.lambda_transport == 0.0 and cfg.train.warmup == 100


def test_bare_word_override_is_a_string():
    assert load_config(None, ["model.ablation=deform-only"]).model.ablation == "deform-only"


def test_round_trip_through_toml(tmp_path):
    cfg = load_config(None, ["model.effects=[\"translation\", \"gravity\"]", "train.iterations=12", "model.step=0.025"])
    path = tmp_path / "c.toml"
    path.write_text(to_toml(cfg))
    assert load_config(path) == cfg


@pytest.mark.parametrize("override, named", [
    ("train.iteration=5", "train.iteration"),
    ("nosuch.key=1", "[nosuch]"),
    ("train.iterations=many", "train.iterations"),
    ("train.iterations=1.5", "train.iterations"),
    ("data.max_time=1.5", "data.max_time"),
    ("data.half_res=1", "data.half_res"),
    ("model.ablation=no-physics", "model.ablation"),
    ("model.integrator=leapfrog", "model.integrator"),
    ("model.effects=[\"magic\"]", "magic"),
    ("model.step=0", "model.step"),
    ("model.scheme=adf-steps", "model.scheme"),
    ("model.carry_offset=-0.05", "model.carry_offset"),
    ("train.lambda_carry=-1", "train.lambda_carry"),
    ("train.carry_horizon=0", "train.carry_horizon"),
    ("train.carry_points=0", "train.carry_points"),
    ("train.motion_only=1", "train.motion_only"),
    ("physics.placement=near", "physics.placement"),
    ("physics.jitter=-0.1", "physics.jitter"),
    # Values of earlier versions are refused, not read as something else.
    ("train.adf_start=window", "train.adf_start"),
    ("train.adf_start=-1", "train.adf_start"),
    ("model.rigid_centre=learned", "model.rigid_centre"),
    ("model.query_code=network", "model.query_code"),
    ("data.background=[2, 0, 0]", "data.background"),
    ("iterations=5", "SECTION.KEY"),
])
def test_bad_values_are_named(override, named):
    with pytest.raises(ValueError, match=named.replace("[", r"\[").replace(".", r"\.")):
        load_config(None, [override])


def test_bad_file_is_named(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[train\niterations = ")
    with pytest.raises(ValueError, match="broken.toml"):
        load_config(path)
    path.write_text("[train]\nwarmup = -1\n")
    with pytest.raises(ValueError, match="broken.toml: train.warmup"):
        load_config(path)


def test_motion_sizes_are_declared_once():
    # The networks' sizes, their defaults and ranges live in NetworkSizes alone: the [model]
    # keys and the resolved MotionSpec carry its very fields, in its order.
    sizes = dataclasses.fields(NetworkSizes)
    for cls in (ModelConfig, MotionSpec):
        fields = {f.name: f for f in dataclasses.fields(cls)}
        assert [fields[f.name].type for f in sizes] == [f.type for f in sizes]
        assert [fields[f.name].default for f in sizes] == [f.default for f in sizes]
    names = [f.name for f in dataclasses.fields(ModelConfig)]
    first = names.index(sizes[0].name)
    assert names[first:first + len(sizes)] == [f.name for f in sizes]  # config.toml's key order


@pytest.mark.parametrize("override", ["model.n_freqs_x=17", "model.n_freqs_x=-1", "model.n_freqs_x=true",
                                      "model.hidden=0", "model.depth=2.0"])
def test_motion_size_out_of_range_is_named(override):
    # The ranges NetworkSizes declares reach the config's validation, with the key and its source.
    key = override.partition("=")[0]
    with pytest.raises(ValueError, match=f"^--set: {key.replace('.', '[.]')}: "):
        load_config(None, [override])


def test_every_key_says_what_it_is_and_why():
    # The descriptions are the fields' docstrings, which `velogauss config` prints.
    rows = describe()
    keys = [f"{section.name}.{field.name}" for section in dataclasses.fields(Config)
            for field in dataclasses.fields(getattr(Config(), section.name))]
    assert [key for key, _, _ in rows] == keys
    assert [key for key, _, text in rows if len(text.split()) < 3] == []
    assert dict((key, value) for key, value, _ in rows)["train.views"] == Config().train.views


def test_velogauss_config_lists_keys_with_the_overrides_applied():
    from typer.testing import CliRunner

    from velogauss.cli import app

    result = CliRunner().invoke(app, ["config", "--set", "train.iterations=7"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    at = lines.index("train.iterations = 7")
    described = dict((k, d) for k, _, d in describe())["train.iterations"].splitlines()
    assert [line.strip() for line in lines[at + 1:at + 1 + len(described)]] == [line.strip() for line in described]
    bad = CliRunner().invoke(app, ["config", "--set", "train.nope=1"])
    assert bad.exit_code == 2 and "train.nope" in bad.output
