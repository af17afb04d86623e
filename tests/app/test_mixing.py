"""velogauss.train.mixing: the mixing weights' "clusters" start (spec/motion.md, VG-COEF, "Initialisation")."""

import numpy as np
import pytest
import torch

from velogauss.config import ModelConfig, load_config
from velogauss.data import load_scene
from velogauss.model.motion import MotionParameters
from velogauss.model.spec import resolve_motion_spec
from velogauss.scenes import make_scene
from velogauss.train import loop
from velogauss.train.mixing import cluster_targets, place_patterns, resolve_mixing_init, separate_patterns
from velogauss_core.constants import MIXING_INIT_WEIGHT
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import mixing_weights

RIGID = dict(effects=("translation", "rotation"), incompressible=False, patterns="mlp")  # `[model]` keys
CENTRES = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.5], [0.0, 0.0, -1.0]])


def _blobs(per_blob=50, spread=0.05, seed=0):
    """Four tight, well-separated blobs of points (4 * per_blob, 3) and each point's blob."""
    rng = np.random.default_rng(seed)
    blob = np.repeat(np.arange(len(CENTRES)), per_blob)
    return CENTRES[blob] + spread * rng.standard_normal((len(blob), 3)), blob


def _weights(motion, x):
    params = motion.params()
    return mixing_weights(params, physics_code(params, x, motion.spec))


def test_kmeans_finds_separated_blobs():
    points, blob = _blobs()
    labels, centres = cluster_targets(points, 4, np.random.default_rng(1))
    # One label per blob, four different labels.
    assert [len(set(labels[blob == b])) for b in range(4)] == [1, 1, 1, 1]
    assert len({labels[blob == b][0] for b in range(4)}) == 4
    np.testing.assert_allclose(np.sort(centres, axis=0), np.sort(CENTRES, axis=0), atol=0.03)


@pytest.mark.spec("VG-COEF")
def test_each_region_starts_on_its_own_pattern():
    spec = resolve_motion_spec(ModelConfig(n_patterns=4, code_dim=4, hidden=16, depth=1, n_freqs_x=1, **RIGID),
                               None, 0.75)
    motion = MotionParameters(spec, np.random.default_rng(0))
    points, blob = _blobs()
    x = torch.tensor(points, dtype=torch.float32)
    before = _weights(motion, x).detach()
    others = {name: p.detach().clone() for name, p in motion.named_parameters()
              if not name.startswith(("code.", "mix."))}
    assert float(before.max(1).values.mean()) < 0.5  # the random start: no pattern dominates
    own = separate_patterns(motion, x, np.random.default_rng(1))
    after = _weights(motion, x).detach()
    assert own == pytest.approx(MIXING_INIT_WEIGHT, abs=0.02)
    dominant = after.argmax(1).numpy()
    # Every blob on one pattern, each blob on a different one, at about the target weight.
    assert [len(set(dominant[blob == b])) for b in range(4)] == [1, 1, 1, 1]
    assert len(set(dominant)) == 4
    np.testing.assert_allclose(after.max(1).values.numpy(), MIXING_INIT_WEIGHT, atol=0.05)
    # Only the code network and the mixing layer are fitted: the patterns, the acceleration
    # and the ADF keep their initial values.
    assert others and all(torch.equal(p, others[name]) for name, p in motion.named_parameters() if name in others)


@pytest.mark.spec("VG-COEF")
def test_training_starts_from_the_clusters(tmp_path):
    make_scene("multi", tmp_path / "multi", resolution=24, n_views=4, n_times=6, n_points=400, n_heldout=1)
    data = load_scene(tmp_path / "multi")
    tiny = ["train.iterations=4", "train.warmup=2", "train.curriculum=1", "model.hidden=16", "model.depth=1",
            "model.n_patterns=8", "physics.n_points=32"]
    spreads = {}
    for start in ("uniform", "clusters"):
        cfg = load_config(None, [*tiny, f"model.mixing_init={start}"])
        trainer, _ = loop.prepare(cfg, data, tmp_path / start)
        m = _weights(trainer.model.motion, trainer.model.gaussians.means).detach()
        spreads[start] = float(m.max(1).values.mean())
        trainer.step(0)  # and it trains from there
    assert spreads["uniform"] < 0.4 < MIXING_INIT_WEIGHT - 0.05 < spreads["clusters"]


@pytest.mark.spec("VG-COEF-CENTRE")
@pytest.mark.parametrize("mixing", ["uniform", "clusters"])
def test_each_pattern_is_centred_on_its_region(mixing):
    spec = resolve_motion_spec(ModelConfig(n_patterns=4, code_dim=4, hidden=16, depth=1, n_freqs_x=1, **RIGID),
                               None, 0.75)
    motion = MotionParameters(spec, np.random.default_rng(0))
    assert float(motion.centre.abs().max()) == 0.0  # the world's origin until placed
    points, blob = _blobs()
    x = torch.tensor(points, dtype=torch.float32)
    place_patterns(motion, x, np.random.default_rng(1), mixing, "clusters")
    centres = motion.centre.numpy()
    if mixing == "clusters":
        # The centres are the blobs' middles, one each (the blobs' own means, not k-means' output),
        # and each blob's dominant pattern is the one centred on that blob.
        means = np.stack([points[blob == b].mean(0) for b in range(4)])
        nearest = np.linalg.norm(centres[:, None] - means[None], axis=-1).argmin(1)
        assert sorted(nearest) == [0, 1, 2, 3]
        np.testing.assert_allclose(centres, means[nearest], atol=1e-5)
        dominant = _weights(motion, x).argmax(1).numpy()
        assert all(nearest[dominant[blob == b]].tolist() == [b] * 50 for b in range(4))
    else:
        # One body: every pattern about the points' mean, the mixing left uniform.
        np.testing.assert_allclose(centres, np.tile(points.mean(0), (4, 1)), atol=1e-6)
        assert float(_weights(motion, x).detach().max(1).values.mean()) < 0.5
    # "origin" leaves the centres at the world's origin.
    fresh = MotionParameters(spec, np.random.default_rng(0))
    place_patterns(fresh, x, np.random.default_rng(1), mixing, "origin")
    assert float(fresh.centre.abs().max()) == 0.0


def test_training_places_the_centres_and_a_checkpoint_keeps_them(tmp_path):
    make_scene("multi", tmp_path / "multi", resolution=24, n_views=4, n_times=6, n_points=400, n_heldout=1)
    data = load_scene(tmp_path / "multi")
    tiny = ["train.iterations=4", "train.warmup=2", "train.curriculum=1", "model.hidden=16", "model.depth=1",
            "model.n_patterns=8", "physics.n_points=32", "model.patterns=mlp", "model.mixing_init=clusters",
            "model.pattern_centres=clusters"]
    trainer, _ = loop.prepare(load_config(None, tiny), data, tmp_path / "run")
    centres = trainer.model.motion.centre.clone()
    means = trainer.model.gaussians.means.detach()
    # Every centre is the mean of the initial points nearest to it (a k-means fixed point), inside their bounds.
    owner = torch.cdist(means, centres).argmin(1)
    for k in owner.unique():
        torch.testing.assert_close(centres[k], means[owner == k].mean(0), rtol=0, atol=1e-4)
    assert len(owner.unique()) > 1
    state = trainer.model.state_dict()
    assert torch.equal(state["motion.centre"], centres)
    trainer, _ = loop.prepare(load_config(None, [*tiny[:-1]]), data, tmp_path / "origin")  # the default
    assert float(trainer.model.motion.centre.abs().max()) == 0.0


def test_a_bad_pattern_centres_names_the_key():
    with pytest.raises(ValueError, match="pattern_centres"):
        load_config(None, ["model.pattern_centres=middle"])


def test_auto_separates_the_patterns_where_a_still_body_sits_beside_moving_ones():
    def spec(**keys):
        return resolve_motion_spec(ModelConfig(**keys), None, 0.75)

    multi, rigid = spec(effects=("translation", "rotation", "static")), spec(**RIGID)
    assert resolve_mixing_init("auto", multi) == "clusters"
    assert resolve_mixing_init("auto", rigid) == "uniform"  # one body: nothing to tell apart
    assert resolve_mixing_init("auto", spec(effects=("static",))) == "uniform"  # nothing moves
    assert resolve_mixing_init("clusters", rigid) == "clusters" and resolve_mixing_init("uniform", multi) == "uniform"


def test_a_bad_mixing_init_names_the_key():
    with pytest.raises(ValueError, match="mixing_init"):
        load_config(None, ["model.mixing_init=kmeans"])


def _entropy(m):
    return float(-(m * torch.log(m)).sum(1).mean())


@pytest.mark.spec("VG-LOSS-MIX")
def test_the_mixing_entropy_sharpens_the_weights_in_training(tmp_path):
    make_scene("multi", tmp_path / "multi", resolution=24, n_views=4, n_times=6, n_points=400, n_heldout=1)
    data = load_scene(tmp_path / "multi")
    tiny = ["train.iterations=12", "train.warmup=2", "train.curriculum=1", "model.hidden=16", "model.depth=1",
            "model.n_patterns=8", "physics.n_points=32", "model.mixing_init=uniform", "train.mix_points=64",
            "train.lr_motion=0.03", "train.lr_motion_final=0.03"]  # a few steps that move the mixing visibly
    entropy = {}
    for weight in (0.0, 1.0):
        cfg = load_config(None, [*tiny, f"train.lambda_mix={weight}"])
        trainer, _ = loop.prepare(cfg, data, tmp_path / f"w{weight}")
        start = _entropy(_weights(trainer.model.motion, trainer.model.gaussians.means).detach())
        for it in range(12):
            trainer.step(it)
        entropy[weight] = _entropy(_weights(trainer.model.motion, trainer.model.gaussians.means).detach())
    # Same draws, same start (log 8 = 2.08 nats is the even spread); only the entropy term differs.
    assert start > 1.5
    assert entropy[1.0] < entropy[0.0] - 0.05, entropy


def test_a_negative_mixing_weight_names_the_key():
    with pytest.raises(ValueError, match="lambda_mix"):
        load_config(None, ["train.lambda_mix=-1"])
