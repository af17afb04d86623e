"""Tests of velogauss/config.py: defaults, TOML files, overrides, and bad values named."""

import pytest

from velogauss.config import Config, load_config, to_toml


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
