"""velogauss.train.optim: parameter groups, learning-rate schedules and the optimiser surgery of
densification."""

import dataclasses
import math

import numpy as np
import pytest
import torch

from velogauss.config import Config, ModelConfig, TrainConfig
from velogauss.model import build_model, scene_spec
from velogauss.model.gaussians import FIELDS
from velogauss.train.optim import make_optimizer, set_learning_rates, update_gaussian_groups

SMALL = dict(n_freqs_x=1, n_freqs_adf_x=1, n_freqs_adf_t=1, code_dim=3, n_patterns=4, hidden=8, depth=1)
TRAIN = TrainConfig(iterations=1000, warmup=200)
EXTENT = 2.5


def _model(effects=("translation", "gravity"), **model):
    """A model of a scene that declares `effects`, taken as declared ("auto" would ignore them)."""
    cfg = Config(model=ModelConfig(effects="declared", **SMALL, **model))
    points = np.random.default_rng(0).uniform(-1, 1, (20, 3))
    spec = scene_spec(cfg, {"effects": list(effects), "incompressible": False})
    return build_model(cfg, spec, points, None, np.random.default_rng(0))


def test_every_parameter_is_in_exactly_one_named_group():
    model = _model(patterns="mlp")
    opt = make_optimizer(model, TRAIN, EXTENT)
    names = [g["name"] for g in opt.param_groups]
    assert names == list(FIELDS) + ["motion", "acc"]
    grouped = [p for g in opt.param_groups for p in g["params"]]
    assert len(grouped) == len({id(p) for p in grouped}) == len(list(model.parameters()))
    assert opt.param_groups[-1]["params"] == [model.motion.acc]


@pytest.mark.parametrize("effects", [("translation", "gravity"), ("translation",)])
def test_rigid_patterns_share_the_acceleration_rate(effects):
    # VG-COEF-RIGID's B holds spins and world positions themselves, as Q holds
    # accelerations: both take the larger rate, with or without an acceleration in the scene.
    model = _model(effects, patterns="rigid")
    groups = {g["name"]: g["params"] for g in make_optimizer(model, TRAIN, EXTENT).param_groups}
    acc = [model.motion.acc] if model.spec.acceleration else []
    assert groups["acc"] == acc + [model.motion.time]
    assert all(p is not q for p in groups["motion"] for q in groups["acc"])


def test_harmonic_coefficients_take_the_acceleration_rate_and_the_frequency_the_networks():
    # VG-COEF-HARM: C holds velocity coefficients themselves; the shared frequency, started
    # where the video oscillates, is only refined, at the networks' rate.
    model = _model(("stretch", "oscillation"), patterns="harmonic")
    groups = {g["name"]: g["params"] for g in make_optimizer(model, TRAIN, EXTENT).param_groups}
    C, omega = model.motion.time
    assert groups["acc"] == [model.motion.acc, C]
    assert any(p is omega for p in groups["motion"])
    assert len([p for g in groups.values() for p in g]) == len(list(model.parameters()))


def test_no_acceleration_group_without_acceleration_and_no_motion_groups_when_static():
    translating = _model(("translation",), patterns="mlp")
    assert [g["name"] for g in make_optimizer(translating, TRAIN, EXTENT).param_groups][-1] == "motion"
    assert [g["name"] for g in make_optimizer(_model(("static",)), TRAIN, EXTENT).param_groups] == list(FIELDS)


def test_schedules_decay_log_linearly_between_their_ends():
    opt = make_optimizer(_model(), TRAIN, EXTENT)

    def lr(it):
        set_learning_rates(opt, it, TRAIN, EXTENT)
        return {g["name"]: g["lr"] for g in opt.param_groups}

    start, middle, end = lr(0), lr(500), lr(1000)
    assert start["means"] == pytest.approx(TRAIN.lr_means * EXTENT)
    assert end["means"] == pytest.approx(TRAIN.lr_means_final * EXTENT)
    assert middle["means"] == pytest.approx(math.sqrt(start["means"] * end["means"]))  # halfway in log space
    # The motion rates run their decay from the warm-up's end, the acceleration's to its own final rate.
    assert lr(200)["motion"] == pytest.approx(TRAIN.lr_motion) and start["motion"] == pytest.approx(TRAIN.lr_motion)
    assert end["motion"] == pytest.approx(TRAIN.lr_motion_final)
    # The acceleration's cooldown: the last tenth of the iterations (900-1000 here) scales it
    # down log-linearly from lr_acc_final's schedule to lr_acc_cooled.
    assert lr(200)["acc"] == pytest.approx(TRAIN.lr_acc) and end["acc"] == pytest.approx(TRAIN.lr_acc_cooled)
    base = lambda it: math.exp(math.log(TRAIN.lr_acc) + (it - 200) / 800 * math.log(TRAIN.lr_acc_final / TRAIN.lr_acc))  # noqa: E731
    assert lr(900)["acc"] == pytest.approx(base(900))
    assert lr(950)["acc"] == pytest.approx(base(950) * math.sqrt(TRAIN.lr_acc_cooled / TRAIN.lr_acc_final))
    assert start["sh_dc"] == end["sh_dc"] == TRAIN.lr_sh and start["sh_rest"] == pytest.approx(TRAIN.lr_sh / 20)


def test_no_cooldown_leaves_the_acceleration_schedule_as_it_was():
    plain = dataclasses.replace(TRAIN, acc_cooldown=0.0)
    opt = make_optimizer(_model(), plain, EXTENT)
    set_learning_rates(opt, plain.iterations, plain, EXTENT)
    assert {g["name"]: g["lr"] for g in opt.param_groups}["acc"] == pytest.approx(plain.lr_acc_final)


def test_update_keeps_the_kept_rows_moments_and_zeroes_the_new_ones():
    model = _model()
    opt = make_optimizer(model, TRAIN, EXTENT)
    (model.gaussians.means.square().sum() + model.gaussians.sh_dc.sum()).backward()
    opt.step()
    before = opt.state[model.gaussians.means]["exp_avg"].clone()
    keep = torch.arange(20) % 3 != 0
    new_rows = {name: torch.zeros((2,) + getattr(model.gaussians, name).shape[1:]) for name in FIELDS}
    update_gaussian_groups(opt, model.gaussians, keep, new_rows)
    means = model.gaussians.means
    assert means.shape == (int(keep.sum()) + 2, 3) and opt.param_groups[0]["params"][0] is means
    moment = opt.state[means]["exp_avg"]
    assert torch.equal(moment[:-2], before[keep]) and not moment[-2:].any()
