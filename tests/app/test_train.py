"""Tests of velogauss/train: curriculum, density control with optimiser surgery, static
detection, atomic checkpoints, exact resume and Ctrl-C."""

import dataclasses
import importlib.metadata
import json
import signal
import threading
import time
import warnings

import numpy as np
import pytest
import torch

from velogauss import io_utils
from velogauss.config import SCHEDULE, DensifyConfig, load_config, resolve_schedule, resolve_transport
from velogauss.data import load_scene
from velogauss.model import build_model, scene_spec
from velogauss.model import motion as motion_fns
from velogauss.scenes import make_scene
from velogauss.train import loop
from velogauss.train.checkpoint import CHECKPOINT_FORMAT, checkpoint_path, load_checkpoint, load_model
from velogauss.train.densify import DensityStats, cap_at, densify_and_prune
from velogauss.train.optim import make_optimizer
from velogauss.train.sampling import FrameSampler, auto_iterations, views_per_iteration, warmup_end
from velogauss.train.static import detect_moving, pixel_footprint
from velogauss.visualize import render_run
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.deform import adf_residual, compose_state
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.motion.coefficients import coefficients as velocity_coefficients
from velogauss_fast.motion.velocity import velocity as affine_velocity

TINY = ["train.iterations=12", "train.warmup=3", "train.curriculum=4", "train.eval_every=6",
        "train.checkpoint_every=4", "densify.start=2", "densify.every=4", "densify.until=10",
        "densify.opacity_reset_every=8", "densify.static_every=4", "physics.n_points=64", "physics.ramp=2",
        "model.hidden=16", "model.depth=1", "model.n_patterns=4", "model.code_dim=4",
        # The toss's declared effects (translation, rotation, gravity) and rigid patterns, what
        # "auto" resolved to before it stopped reading scene.json: these tests are not about the
        # motion form, and an "auto" form would first train a backtest probe (velogauss.train.backtest;
        # tests/app/test_end_to_end.py trains the real default).
        "model.effects=declared", "model.patterns=rigid"]


@pytest.fixture(scope="module")
def tiny_scene(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "toss"
    make_scene("toss", path, resolution=24, n_views=4, n_times=6, n_points=300, n_heldout=1)
    return load_scene(path)


def test_curriculum_opens_the_time_window():
    times = [0.0, 0.25, 0.5, 0.75] * 2
    sampler = FrameSampler(times, warmup=10, curriculum=20, moving=True)
    rng = np.random.default_rng(0)
    assert {times[sampler.sample(it, rng)] for it in range(10) for _ in range(5)} == {0.0}
    assert sampler.window(10) == pytest.approx(0.75 / 20)
    assert sampler.window(29) == pytest.approx(0.75)
    drawn = {times[sampler.sample(40, rng)] for _ in range(200)}
    assert drawn == {0.0, 0.25, 0.5, 0.75}
    static = FrameSampler(times, warmup=10, curriculum=20, moving=False)
    assert static.window(0) == 0.75  # nothing moves: every frame from the start


def test_a_monocular_warmup_draws_its_first_frames_and_a_rig_its_start():
    """spec/density.md, "The warm-up's views"."""
    mono = np.arange(150) / 149.0  # one camera per time, as D-NeRF
    sampler = FrameSampler(mono, warmup=10, curriculum=200, moving=True, views=3, warmup_views=8)
    rng = np.random.default_rng(0)
    assert {sampler.sample(it, rng) for it in range(10) for _ in range(40)} == set(range(8))
    assert sampler.window(10) == pytest.approx(7 / 149)  # the curriculum opens from there, not back to t = 0
    assert sampler.window(209) == pytest.approx(1.0)
    # A short clip: the eighth frame lies past a tenth of the window, so the warm-up stops there.
    assert warmup_end(np.arange(20) / 19.0, 3, 8) == pytest.approx(0.1)
    # A rig whose start has train.views cameras keeps the start alone; two cameras do not.
    assert warmup_end(np.repeat(np.arange(20) / 19.0, 3), 3, 8) == 0.0
    assert warmup_end(np.repeat(np.arange(40) / 39.0, 2), 3, 8) == pytest.approx(3 / 39)
    assert warmup_end(mono, 3, 1) == 0.0  # one view, the default: the start
    assert load_config().train.warmup_views == 1


def test_views_of_a_step_share_one_time_and_differ_in_camera():
    times = np.repeat([0.0, 0.25, 0.5], 4)  # 4 cameras per time
    sampler = FrameSampler(times, warmup=0, curriculum=1, moving=True)
    rng = np.random.default_rng(0)
    for _ in range(50):
        views = sampler.sample_views(5, rng, 3)
        assert len(views) == len(set(views)) == 3
        assert len({times[i] for i in views}) == 1
    # More views than cameras at that time: every camera once.
    views = sampler.sample_views(5, rng, 9)
    assert sorted(views) == list(np.flatnonzero(times == times[views[0]]))
    assert len(sampler.sample_views(5, rng, 1)) == 1


def test_the_auto_budget_renders_as_many_views_as_a_multiview_run():
    """spec/density.md, "The iteration budget": 3,000 x views / (mean views an iteration finds)."""
    multiview = np.repeat([0.0, 0.25, 0.5], 4)  # 4 cameras per time
    monocular = np.linspace(0.0, 1.0, 50)  # D-NeRF: one camera per time
    mixed = [0.0, 0.0, 0.5, 0.5, 0.5, 1.0]  # frames with 2, 2, 3, 3, 3 and 1 views at views = 3
    assert views_per_iteration(multiview, 3) == 3 and auto_iterations(multiview, 3) == 3000
    assert views_per_iteration(monocular, 3) == 1 and auto_iterations(monocular, 3) == 9000
    assert views_per_iteration(mixed, 3) == pytest.approx(14 / 6)
    assert auto_iterations(mixed, 3) == round(3000 * 3 / (14 / 6)) == 3857
    assert auto_iterations(np.repeat([0.0, 0.5], 2), 3) == 4500
    assert auto_iterations(monocular, 1) == 3000  # one view asked, one found
    assert auto_iterations(monocular, 3, moving=False) == 3000  # a still scene's frames all go together


def test_the_default_scene_keeps_the_budget_every_benchmark_measured(tmp_path):
    """The main job's scene films every time with more cameras than train.views: 3,000, as before."""
    from velogauss.scenes import DEFAULT_SCENE

    make_scene(DEFAULT_SCENE, tmp_path / "scene", resolution=16)
    scene = load_scene(tmp_path / "scene")
    assert auto_iterations([f.time for f in scene.train], load_config().train.views) == 3000


def test_the_auto_budget_is_recorded_and_kept_on_resume(tiny_scene, tmp_path, monkeypatch):
    """train.iterations "auto" becomes a number from the training frames (the tiny toss: 3
    training cameras at every time, so 3,000 at 3 views and 9,000 at one camera's worth), which
    config.toml records and a resume with "auto" keeps."""
    # A stand-in for the 3,000 of every benchmarked run, so that the tiny scene trains in seconds.
    monkeypatch.setattr("velogauss.train.sampling.SCHEDULE_ITERATIONS", 4)
    auto = [item for item in TINY if item.split("=")[0] not in SCHEDULE and item.split("=")[0] != "train.iterations"]
    assert load_config(None, auto).train.iterations == "auto"
    loop.train(load_config(None, auto + ["train.views=2"]), tiny_scene, tmp_path / "multi", progress=False)
    assert load_config(tmp_path / "multi" / "config.toml").train.iterations == 4
    first = tiny_scene.train[0].camera.viewmat
    monocular = dataclasses.replace(tiny_scene, train=[f for f in tiny_scene.train
                                                       if np.array_equal(f.camera.viewmat, first)])
    loop.train(load_config(None, auto + ["train.views=2"]), monocular, tmp_path / "mono", progress=False)
    assert load_config(tmp_path / "mono" / "config.toml").train.iterations == 8
    loop.train(load_config(None, auto + ["train.views=2"]), monocular, tmp_path / "mono", resume=True, progress=False)
    assert load_config(tmp_path / "mono" / "config.toml").train.iterations == 8


@pytest.mark.parametrize("iterations, resets", [(12, []), (16, [8])])
def test_an_opacity_reset_needs_a_period_of_training_after_it(tiny_scene, tmp_path, monkeypatch, iterations, resets):
    """TINY resets every 8 iterations up to 10: at 8 of 16 (8 left), not at 8 of 12 (4 left)."""
    current, resets_at = {}, []
    monkeypatch.setattr(loop, "reset_opacity", lambda model, optimizer: resets_at.append(current["done"]))
    adapt_gaussians = loop.Trainer.adapt_gaussians

    def recording(self, done):
        current["done"] = done
        adapt_gaussians(self, done)

    monkeypatch.setattr(loop.Trainer, "adapt_gaussians", recording)
    loop.train(load_config(None, TINY + [f"train.iterations={iterations}"]), tiny_scene, tmp_path, progress=False)
    assert resets_at == resets


def test_a_schedule_too_short_for_its_curriculum_warns_naming_the_keys():
    # TINY opens the window at 3 + 4 = 7: 12 iterations leave 5 (>= 4), 8 leave 1.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loop.warn_short_schedule(load_config(None, TINY).train)
    with pytest.warns(UserWarning, match=r"train.iterations = 8: .* leaving 1 iterations .* train.curriculum"):
        loop.warn_short_schedule(load_config(None, TINY + ["train.iterations=8"]).train)
    with pytest.warns(UserWarning, match="leaving 600"):
        loop.warn_short_schedule(load_config(None, ["train.iterations=2000", "train.warmup=200",
                                                    "train.curriculum=1200"]).train)
    with warnings.catch_warnings():  # the "auto" schedule scales with the run
        warnings.simplefilter("error")
        loop.warn_short_schedule(resolve_schedule(load_config(None, ["train.iterations=2000"])).train)


# Tests that set the time network's last layer by hand (VG-COEF), on a scene whose rigid
# effects TINY gives rigid patterns (VG-COEF-RIGID).
MLP_PATTERNS = ["model.patterns=mlp"]


def _model(tiny_scene, overrides=()):
    cfg = load_config(None, TINY + list(overrides))
    spec = scene_spec(cfg, tiny_scene.metadata)
    return cfg, build_model(cfg, spec, tiny_scene.points, tiny_scene.point_colors, np.random.default_rng(0))


def test_densify_carries_adam_moments_with_the_gaussians(tiny_scene, device):
    # On CUDA too: the split noise comes from the CPU generator the loop seeds (the first
    # GPU run found it drawn on the CPU and added to CUDA means).
    cfg, model = _model(tiny_scene)
    model.to(device)
    opt = make_optimizer(model, cfg.train, extent=4.0)
    g = model.gaussians
    n = len(g)
    # One real step so that every Gaussian field has Adam moments.
    (g.means.square().sum() + g.sh_dc.sum() + g.log_scales.sum() + g.quats.sum() + g.opacity_logits.sum()
     + g.sh_rest.sum()).backward()
    opt.step()
    old_means = g.means.detach().clone()
    old_moment = opt.state[g.means]["exp_avg"].clone()
    stats = DensityStats(n, device)
    stats.grad[:5] = 1.0  # five hot Gaussians
    stats.count[:] = 1.0
    with torch.no_grad():
        g.opacity_logits[-3:] = -20.0  # three transparent ones, to be pruned
        g.log_scales[:2] = np.log(10.0)  # two large ones among the hot: split, not cloned
        g.log_scales[2:5] = np.log(0.01)  # three small ones: cloned (0.01 < percent_dense * 4)
    out = densify_and_prune(model, opt, stats, cfg.densify, extent=4.0, image_size=64, after_reset=False,
                            generator=torch.Generator().manual_seed(0), done=cfg.densify.start + 1)
    assert out == {"cloned": 3, "split": 2, "pruned": 3, "total": n - 3 - 2 + 3 + 4}
    assert len(g) == len(model.moving) == out["total"]
    # The kept rows keep their values and moments, in order; new rows start with zero moments.
    kept = n - 5
    assert torch.equal(g.means[: kept - 0][:3], old_means[2:5])
    moment = opt.state[g.means]["exp_avg"]
    assert torch.equal(moment[:3], old_moment[2:5])
    assert torch.all(moment[kept:] == 0)
    assert opt.param_groups[0]["params"][0] is g.means
    # Split children are drawn around their parent with scales / 1.6.
    children = g.log_scales[-4:].exp()
    assert torch.allclose(children, torch.full_like(children, 10.0 / 1.6))


@pytest.mark.parametrize("image_size, pruned", [(64, 2), (128, 2), (400, 1), (800, 0)])
def test_screen_size_pruning_grows_with_the_image_past_128_px(tiny_scene, image_size, pruned):
    # After a reset, radii above max(20 px, 20/128 of the larger side) go: 30 px and 100 px on a
    # 64 or 128 px image (15 px stays: 3DGS's 20 px is the floor), 100 px on a 400 px one (62.5
    # px), none on an 800 px one (125 px).
    cfg, model = _model(tiny_scene)
    opt = make_optimizer(model, cfg.train, extent=4.0)
    n = len(model.gaussians)
    stats = DensityStats(n)
    stats.count[:] = 1.0
    stats.max_radius[:3] = torch.tensor([15.0, 30.0, 100.0])
    with torch.no_grad():
        model.gaussians.opacity_logits.fill_(0.0)  # opaque: no pruning by opacity
        model.gaussians.log_scales.fill_(np.log(0.01))  # small in the world
    out = densify_and_prune(model, opt, stats, cfg.densify, extent=4.0, image_size=image_size, after_reset=True,
                            generator=torch.Generator().manual_seed(0), done=cfg.densify.start + 1)
    assert out == {"cloned": 0, "split": 0, "pruned": pruned, "total": n - pruned}


@pytest.mark.parametrize("schedule, done_share, room", [("fixed", 0.1, 4), ("linear", 1.0, 4),
                                                       ("linear", 2.0, 4), ("linear", 0.998, 3)])
def test_densify_respects_the_gaussian_budget(tiny_scene, schedule, done_share, room):
    # The cap is max_gaussians, or under "linear" its share (done - start) / (until - start):
    # here 304 Gaussians at the window's end and after it, int(304 * 0.998) = 303 just before.
    cfg, model = _model(tiny_scene, [f"densify.max_gaussians={300 + 4}", f"densify.cap_schedule={schedule}",
                                     "densify.start=100", "densify.until=600"])
    opt = make_optimizer(model, cfg.train, extent=4.0)
    n = len(model.gaussians)
    assert n == 300
    stats = DensityStats(n)
    stats.grad[:] = torch.linspace(1.0, 2.0, n)  # every Gaussian hot, the last ones hottest
    stats.count[:] = 1.0
    with torch.no_grad():
        model.gaussians.log_scales.fill_(np.log(0.01))  # all small: candidates for cloning
    hottest = model.gaussians.means[-room:].detach().clone()
    out = densify_and_prune(model, opt, stats, cfg.densify, extent=4.0, image_size=64, after_reset=False,
                            generator=torch.Generator().manual_seed(0), done=round(100 + 500 * done_share))
    assert out["total"] == n + room and out["cloned"] == room
    assert torch.equal(model.gaussians.means[-room:], hottest)


@pytest.mark.parametrize("done, cap", [(0, 0), (100, 0), (350, 5000), (599, 9980), (600, 10000), (3000, 10000)])
def test_linear_cap_rises_over_the_densification_window(done, cap):
    d = DensifyConfig(start=100, until=600, cap_schedule="linear")
    assert cap_at(d, done) == cap
    assert cap_at(DensifyConfig(start=100, until=600), done) == 10000


def test_static_detection(tiny_scene):
    cfg, model = _model(tiny_scene, MLP_PATTERNS)
    # A fresh model is still (zero velocity and ADF heads): everything is static.
    assert not detect_moving(model, 0.75, 1e-4).any()
    # Translation w1 = 1 everywhere: every particle moves 0.75 by t = 0.75.
    with torch.no_grad():
        model.motion.time[-1].copy_(torch.tensor([1.0] + [0.0] * 11).repeat(cfg.model.n_patterns))
    assert detect_moving(model, 0.75, 1e-4).all()
    assert model.moving.all()  # detection leaves the flags alone
    # A per-particle threshold: those allowed more than the 0.75 they move stay static.
    threshold = torch.full((len(model.gaussians),), 0.5)
    threshold[::3] = 1.0
    assert torch.equal(detect_moving(model, 0.75, threshold), threshold < 0.75)


def test_pixel_footprint_is_depth_over_focal_in_the_closest_camera():
    from velogauss.data import Camera

    K = np.array([[100.0, 0, 16], [0, 100.0, 16], [0, 0, 1]])
    near = np.eye(4)
    near[2, 3] = 2.0   # world z = 0 is 2 in front of this camera
    far = np.eye(4)
    far[2, 3] = 5.0
    behind = np.diag([1.0, -1.0, -1.0, 1.0])  # looks the other way: z = 0 is 0 deep, z = 1 behind it
    cameras = [Camera(far, K, 32, 32), Camera(near, K, 32, 32), Camera(behind, K, 32, 32)]
    points = torch.tensor([[0.0, 0.0, 0.0], [0.3, -0.2, 1.0], [0.0, 0.0, -10.0]], dtype=torch.float64)
    size = pixel_footprint(points, cameras)
    # depths: point 0 -> 5, 2, 0 (not in front); point 1 -> 6, 3, -1; point 2 -> -5, -8, 10.
    assert size.tolist() == pytest.approx([2.0 / 100, 3.0 / 100, 10.0 / 100])
    assert torch.isinf(pixel_footprint(points[2:], cameras[:2])).all()


def test_static_particles_are_rendered_canonical(tiny_scene):
    cfg, model = _model(tiny_scene, MLP_PATTERNS)
    with torch.no_grad():
        model.motion.time[-1].copy_(torch.tensor([1.0] + [0.0] * 11).repeat(cfg.model.n_patterns))
    moving = torch.zeros(len(model.gaussians), dtype=torch.bool)
    moving[::2] = True
    model.set_moving(moving)
    x0 = model.gaussians.means.detach()
    means = model.state_at(0.5)[0].detach()
    assert torch.equal(means[~moving], x0[~moving])
    assert torch.allclose(means[moving] - x0[moving], torch.tensor([0.5, 0.0, 0.0]).expand(int(moving.sum()), 3),
                          atol=1e-5)


def test_auto_schedule_is_recorded_and_kept_on_resume(tiny_scene, tmp_path):
    """config.toml holds the numbers a run's "auto" schedule resolved to, and a resume that
    trains longer keeps them rather than stretching the schedule mid-run; provenance.json holds
    both sessions."""
    auto = [item for item in TINY if item.split("=")[0] not in SCHEDULE]
    loop.train(load_config(None, auto + ["train.iterations=6"]), tiny_scene, tmp_path, progress=False)
    first = load_config(tmp_path / "config.toml")
    assert (first.train.warmup, first.train.curriculum, first.densify.until, first.densify.every) == (0, 2, 4, 1)
    loop.train(load_config(None, auto + ["train.iterations=9"]), tiny_scene, tmp_path, resume=True, progress=False)
    resumed = load_config(tmp_path / "config.toml")
    assert resumed.train.iterations == 9
    assert dataclasses.replace(resumed, train=dataclasses.replace(resumed.train, iterations=6)) == first
    sessions = json.loads((tmp_path / "provenance.json").read_text())
    assert [s["iteration"] for s in sessions] == [0, 6]
    assert all(s["version"] == importlib.metadata.version("velogauss") for s in sessions)


def test_a_run_of_the_default_form_resumes_with_the_form_it_chose(tiny_scene, tmp_path):
    """model.patterns "auto": the backtest's choice is recorded like the schedule's numbers, and a
    resume with the same config keeps it."""
    default = [item for item in TINY if item.split("=")[0] not in ("model.effects", "model.patterns")]
    loop.train(load_config(None, default + ["train.iterations=4"]), tiny_scene, tmp_path, progress=False)
    first = load_config(tmp_path / "config.toml")
    assert first.model.patterns != "auto" and (tmp_path / "motion_form.json").is_file()
    loop.train(load_config(None, default + ["train.iterations=6"]), tiny_scene, tmp_path, resume=True, progress=False)
    resumed = load_config(tmp_path / "config.toml")
    assert resumed.train.iterations == 6 and resumed.model == first.model


def test_checkpoint_write_is_atomic(tiny_scene, tmp_path, monkeypatch):
    cfg = load_config(None, TINY + ["train.iterations=4"])
    loop.train(cfg, tiny_scene, tmp_path, progress=False)
    before = checkpoint_path(tmp_path).read_bytes()

    fsync = io_utils._fsync

    def broken_fsync(path):  # the checkpoint's temporary file is half written when the disk fills
        if path.name.startswith(".latest.pt."):
            path.write_bytes(b"half a checkpo")
            raise OSError("disk full")
        fsync(path)

    monkeypatch.setattr(io_utils, "_fsync", broken_fsync)
    with pytest.raises(OSError, match="disk full"):
        loop.train(load_config(None, TINY + ["train.iterations=8"]), tiny_scene, tmp_path, resume=True,
                   progress=False)
    assert checkpoint_path(tmp_path).read_bytes() == before
    assert [p.name for p in checkpoint_path(tmp_path).parent.iterdir()] == ["latest.pt"]


def test_a_checkpoint_carries_its_format_version(tiny_scene, tmp_path):
    loop.train(load_config(None, TINY + ["train.iterations=2"]), tiny_scene, tmp_path, progress=False)
    first, _, data = checkpoint_path(tmp_path).read_bytes().partition(b"\n")
    assert f"format_version={CHECKPOINT_FORMAT} ".encode() in first
    assert load_checkpoint(tmp_path)["iteration"] == 2
    tampered = first.replace(f"format_version={CHECKPOINT_FORMAT}".encode(), b"format_version=1")
    checkpoint_path(tmp_path).write_bytes(tampered + b"\n" + data)
    expected = (f"{checkpoint_path(tmp_path)}: checkpoint format version 1, expected version {CHECKPOINT_FORMAT}: "
                ".*retrain with this version, or check out the release that wrote it")
    with pytest.raises(ValueError, match=expected):
        load_checkpoint(tmp_path)
    with pytest.raises(ValueError, match="version 1"):
        load_model(tmp_path)
    # An old-style header, with no version (velogauss-checkpoint/2 sha256=...): refused the same way.
    digest = first.split(b"sha256=")[1]
    checkpoint_path(tmp_path).write_bytes(b"velogauss-checkpoint/2 sha256=" + digest + b"\n" + data)
    with pytest.raises(ValueError, match=f"checkpoint format no version, expected version {CHECKPOINT_FORMAT}: "):
        load_checkpoint(tmp_path)
    with pytest.raises(ValueError, match="no version"):
        loop.train(load_config(None, TINY + ["train.iterations=4"]), tiny_scene, tmp_path, resume=True,
                   progress=False)


def test_ctrl_c_checkpoints_and_resume_continues_exactly(tiny_scene, tmp_path, monkeypatch):
    cfg = load_config(None, TINY)
    full = loop.train(cfg, tiny_scene, tmp_path / "full", progress=False)
    wall = time.perf_counter()
    step = loop.Trainer.step

    def step_then_interrupt(self, it):
        out = step(self, it)
        if it == 5:  # between checkpoints (every 4) and evaluations (every 6)
            signal.raise_signal(signal.SIGINT)
        return out

    monkeypatch.setattr(loop.Trainer, "step", step_then_interrupt)
    # The handler the training found is put back, whatever it was (the test process's is
    # usually Python's default, but a library loaded by an earlier test may have set another).
    handler = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt, match="iteration 6"):
        loop.train(cfg, tiny_scene, tmp_path / "cut", progress=False)
    cut = load_checkpoint(tmp_path / "cut")
    assert cut["iteration"] == 6
    assert loop.RunState(**cut["extra"]).elapsed_s > 0  # the run state travels in the checkpoint
    assert signal.getsignal(signal.SIGINT) is handler
    monkeypatch.setattr(loop.Trainer, "step", step)
    resumed = loop.train(cfg, tiny_scene, tmp_path / "cut", resume=True, progress=False)
    # Same draws, same densification, same numbers: bit for bit on the CPU.
    a, b = full.state_dict(), resumed.state_dict()
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key
    wall = time.perf_counter() - wall
    log = [json.loads(line) for line in (tmp_path / "cut" / "log.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in log] == [6, 12]
    # Training time adds up over both sessions without counting any stretch twice.
    assert 0 < log[0]["elapsed_s"] < log[1]["elapsed_s"] < wall
    # The process's peak resident memory never falls (VmHWM), and a torch process holds over 100 MiB.
    assert 100 < log[0]["peak_rss_mib"] <= log[1]["peak_rss_mib"]
    model, saved_cfg = load_model(tmp_path / "cut")
    # The checkpoint holds the config with its "auto" keys resolved (TINY's rigid patterns on toss).
    assert saved_cfg == resolve_transport(resolve_schedule(cfg), "rigid")
    assert load_checkpoint(tmp_path / "cut")["iteration"] == 12


@pytest.mark.parametrize("ablation", ["no-pds", "no-adf", "no-gpc", "deform-only"])
def test_every_ablation_trains_and_reloads(tiny_scene, tmp_path, ablation):
    cfg = load_config(None, TINY + [f"model.ablation={ablation}", "train.iterations=8"])
    reloaded = _trains_and_reloads(cfg, tiny_scene, tmp_path)
    has_velocity = ablation != "deform-only"
    assert reloaded.has_velocity == has_velocity
    assert reloaded.spec.adf == (ablation != "no-adf")
    assert hasattr(reloaded.motion, "adf") == reloaded.spec.adf
    # Its pictures: a velocity field figure only where there is a velocity field.
    written = {p.name for p in render_run(reloaded, tiny_scene, tmp_path / "renders")}
    assert {"sequence.mp4", "sequence.gif", "filmstrip.png", "trajectories.png"} <= written
    assert ("velocity_field.png" in written) == has_velocity


def test_particle_velocity_keeps_the_start_code(tiny_scene):
    # The code network's answer between the Gaussians (VG-FIELD, velogauss.model.motion's pure
    # functions); the model's, VG-FIELD-GAUSS, is tested below.
    cfg, model = _model(tiny_scene, MLP_PATTERNS)
    with torch.no_grad():
        last = model.motion.time[-1]
        last.copy_(torch.randn(last.shape, generator=torch.Generator().manual_seed(0)))
        x0 = torch.rand(64, 3, generator=torch.Generator().manual_seed(1)) - 0.5
        x = x0 + 0.3
        params, spec = model.motion.params(), model.spec
        # At its own start the particle velocity is the Eulerian field (same code) ...
        assert torch.allclose(motion_fns.particle_velocity(params, spec, x0, x0, 0.4),
                              motion_fns.velocity_at(params, spec, x0, 0.4), atol=1e-6)
        # ... elsewhere it keeps the start's code, where the field reads the code at x.
        moved = motion_fns.particle_velocity(params, spec, x0, x, 0.4)
        field = motion_fns.velocity_at(params, spec, x, 0.4)
        assert (moved - field).abs().max() > 1e-3
        cfg_m = spec
        w = velocity_coefficients(params, 0.4, physics_code(params, x0, cfg_m), cfg_m)
        assert torch.allclose(moved, affine_velocity(x, w), atol=1e-6)


@pytest.mark.spec("VG-FIELD-GAUSS")
def test_velocity_between_the_gaussians(tiny_scene):
    # VG-FIELD-GAUSS, the default: on a Gaussian's canonical mean a particle moves with that
    # Gaussian's own weights; a static Gaussian lends zero weights; the Eulerian field takes
    # the weights of the Gaussians nearest at time t, so on each Gaussian's physics position
    # it is that Gaussian's own velocity.
    cfg, model = _model(tiny_scene, MLP_PATTERNS)
    assert model.spec.query_code == "gaussians"
    with torch.no_grad():
        last = model.motion.time[-1]
        last.copy_(torch.randn(last.shape, generator=torch.Generator().manual_seed(0)))
        params, cfg_m = model.motion.params(), model.spec
        mu = model.gaussians.means
        own = affine_velocity(mu, velocity_coefficients(params, 0.4, physics_code(params, mu, cfg_m), cfg_m))
        torch.testing.assert_close(model.particle_velocity(mu, mu, 0.4), own, rtol=1e-4, atol=1e-5)
        x_star = model.tracked_positions(0.4)
        at_star = affine_velocity(x_star, velocity_coefficients(params, 0.4, physics_code(params, mu, cfg_m), cfg_m))
        torch.testing.assert_close(model.velocity_at(x_star, 0.4), at_star, rtol=1e-4, atol=1e-5)
        # Between the Gaussians it differs from the code network's answer.
        x0 = torch.rand(64, 3, generator=torch.Generator().manual_seed(1)) - 0.5
        network = velocity_coefficients(params, 0.4, physics_code(params, x0, cfg_m), cfg_m)
        assert (model.particle_velocity(x0, x0, 0.4) - affine_velocity(x0, network)).abs().max() > 1e-3
        # With every Gaussian static, nothing moves: every row of the weights is zero.
        model.set_moving(torch.zeros(len(mu), dtype=torch.bool))
        assert torch.equal(model.particle_velocity(x0, x0, 0.4), torch.zeros_like(x0))
        assert torch.equal(model.velocity_at(x0, 0.4), torch.zeros_like(x0))


@pytest.mark.parametrize("extra", [["model.scheme=adf-step"], ["model.scheme=adf-step", "model.ablation=no-pds"],
                                   ["model.scheme=adf-step", "train.lambda_carry=1.0", "train.carry_points=16"],
                                   ["physics.placement=box"], ["model.acceleration=rigid"],
                                   ["model.acceleration=auto", "model.ablation=no-pds"], ["train.motion_only=true"],
                                   ["model.patterns=mlp"], ["model.patterns=rigid", "model.scheme=adf-step"],
                                   ["model.patterns=harmonic"], ["model.patterns=harmonic", "model.scheme=adf-step"]])
def test_schemes_and_options_train_and_reload(tiny_scene, tmp_path, extra):
    cfg = load_config(None, TINY + extra)
    _trains_and_reloads(cfg, tiny_scene, tmp_path)


def test_adf_step_scheme_renders_the_adf_inside_the_window_and_the_velocity_beyond(tiny_scene):
    # VG-CARRY: inside the window (offset 0) the ADF's state; past max_time the ADF's state at
    # max_time moved by the velocity, whose last layer is non-zero after this perturbation.
    cfg, model = _model(tiny_scene, ["model.scheme=adf-step"])
    spec = model.spec
    assert spec.scheme == "adf-step" and spec.carry_until == cfg.data.max_time and spec.carry_loss
    assert not spec.adf_loss  # x = x* under scheme (b): no displacement to penalise
    with torch.no_grad():
        for p in model.motion.parameters():
            p.add_(0.05 * torch.randn_like(p))
    params = model.motion.params()
    x0, q0, s0 = model.gaussians.means, torch.nn.functional.normalize(model.gaussians.quats, dim=1), model.gaussians.scales
    z = physics_code(params, x0, spec)

    def adf_state(t):
        return compose_state(x0, q0, s0, *adf_residual(params, x0, t, z, spec))

    def step(state, t0, t):
        return base_state(params, *state, z, t, spec.step, spec.integrator, spec, t0=t0)

    with torch.no_grad():
        inside = model.state_at(0.5)[0]
        torch.testing.assert_close(inside, adf_state(0.5)[0])
        beyond = model.state_at(0.9)[0]
        torch.testing.assert_close(beyond, step(adf_state(spec.carry_until), spec.carry_until, 0.9)[0])
        assert (beyond - adf_state(spec.carry_until)[0]).norm(dim=1).max() > 1e-4  # the velocity moved them
        # A training offset starts the step one frame away.
        stepped = model.state_at(0.5, offset=0.05)[0]
        torch.testing.assert_close(stepped, step(adf_state(0.45), 0.45, 0.5)[0])


def test_adf_step_needs_a_velocity_and_an_adf(tiny_scene):
    # Without an ADF (no-adf) or a velocity (deform-only) there is nothing to carry: the scheme
    # resolves to "integrate", and so does training before the ADF starts.
    for ablation in ("no-adf", "deform-only"):
        _, model = _model(tiny_scene, ["model.scheme=adf-step", f"model.ablation={ablation}"])
        assert model.spec.scheme == "integrate" and model.spec.carry_until is None and not model.spec.carry_loss
    _, model = _model(tiny_scene, ["model.scheme=adf-step", "model.ablation=no-pds"])
    assert model.spec.scheme == "adf-step" and not model.spec.carry_loss  # VG-LOSS-CARRY is the affine velocity's
    assert model.spec.without_adf().scheme == "integrate"


def test_collocation_draws_near_points_stay_within_the_jitter():
    from velogauss.train.sampling import draw_near

    points = torch.tensor([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    index, offsets = draw_near(len(points), 500, 0.01, np.random.default_rng(0), torch.float32, "cpu")
    x = points.index_select(0, index) + offsets
    nearest = torch.cdist(x, points).min(dim=1).values
    assert x.shape == (500, 3) and offsets.dtype == torch.float32 and nearest.max() < 0.06  # 6 sigma of a 3D normal
    assert (torch.cdist(x, points).argmin(dim=1) == 0).any() and (torch.cdist(x, points).argmin(dim=1) == 1).any()


def _trains_and_reloads(cfg, scene, run_dir):
    """Train `cfg`, reload the run, check both render the first future frame finite and
    identically; return the reloaded model."""
    model = loop.train(cfg, scene, run_dir, progress=False)
    reloaded, _ = load_model(run_dir)
    frame = scene.extrapolation[0]
    with torch.no_grad():
        a = model.render(frame.camera, frame.time, scene.background)[0]
        b = reloaded.render(frame.camera, frame.time, scene.background)[0]
    assert torch.isfinite(a).all() and torch.equal(a, b)
    return reloaded


def test_aux_losses_in_the_worker_train_as_inline_to_the_last_bit(tiny_scene, tmp_path, monkeypatch):
    # The physics, carry and mixing losses run in a worker process beside the renders
    # (velogauss.train.aux_worker); their draws come first and their gradients join in a
    # fixed order, so whether a worker ran changes no number of the training. With the worker,
    # the ADF's backward runs in a thread of its own too (velogauss.train.adf_backward_thread),
    # from the iteration the ADF starts: the same numbers again.
    from velogauss.train import aux_losses, aux_worker
    from velogauss.train.adf_backward_thread import AdfBackwardJob

    submitted, inline, adf_in = [], [], []
    send = aux_worker.AuxWorker.submit
    monkeypatch.setattr(aux_worker.AuxWorker, "submit", lambda self, *a: (submitted.append(1), send(self, *a))[1])
    traced = aux_losses.loss_and_gradients  # in this process: the inline runs only
    monkeypatch.setattr(aux_losses, "loss_and_gradients", lambda *a: (inline.append(1), traced(*a))[1])
    handed = AdfBackwardJob.start_backward
    monkeypatch.setattr(AdfBackwardJob, "start_backward", lambda self, g: (adf_in.append(1), handed(self, g))[1])
    # The default threads with a budget of two (OMP_NUM_THREADS): one torch thread, as every
    # test has, and two compositing threads, so the worker (torch's own count stays 1 here).
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    cfg = load_config(None, TINY)
    trained = {}
    for worker in (True, False):
        trainer, _ = loop.prepare(cfg, tiny_scene, tmp_path / str(worker))
        assert isinstance(trainer.aux_worker, aux_worker.AuxWorker)
        if not worker:
            trainer.aux_worker = None
        first = max(cfg.train.warmup, trainer.adf_start - 3)  # 3 iterations without the ADF, 3 with it
        losses = [trainer.step(it) for it in range(first, first + 6)]
        trained[worker] = ({k: v.detach().clone() for k, v in trainer.model.state_dict().items()}, losses)
    assert len(submitted) == len(inline) == 6, "the auxiliary losses ran in the worker process, then inline"
    assert len(adf_in) == 3, "the ADF's backward ran in its thread on the worker's iterations with the ADF"
    (a, loss_a), (b, loss_b) = trained[True], trained[False]
    assert loss_a == loss_b
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("cores, worker, during", [(2, True, 1), (2, False, 2), (4, True, 3), (1, False, 1)])
def test_the_renders_leave_the_aux_worker_a_core(tiny_scene, tmp_path, monkeypatch, cores, worker, during):
    # With the auxiliary losses' worker the step's compositing takes one thread fewer than the
    # run's, at least one, and gives it back after the step.
    from velogauss_fast.backends import numba_backend

    monkeypatch.setenv("OMP_NUM_THREADS", str(cores))
    monkeypatch.setattr(numba_backend, "_THREADS", numba_backend._THREADS)  # prepare sets it: restored after
    trainer, _ = loop.prepare(load_config(None, TINY), tiny_scene, tmp_path)
    assert (trainer.aux_worker is not None) == (cores >= 2) and numba_backend.get_num_threads() == cores
    if not worker:
        trainer.aux_worker = None  # (2, False): the auxiliary losses inline, as the test above runs them
    seen = []
    rendered = loop.render_gaussians
    monkeypatch.setattr(loop, "render_gaussians",
                        lambda *a: (seen.append(numba_backend.get_num_threads()), rendered(*a))[1])
    trainer.step(trainer.cfg.train.warmup)
    assert seen and set(seen) == {during}
    assert numba_backend.get_num_threads() == cores


@pytest.mark.parametrize("overrides, start", [
    ([], "window"),  # rigid patterns (toss): the patterns learn the motion before the ADF
    (["model.patterns=mlp"], "warmup"),  # the time network: the ADF starts with the motion
    (["model.ablation=deform-only"], "warmup"),  # its ADF is the motion
    (["model.scheme=adf-step"], "warmup"),  # its ADF carries the window
    (["model.patterns=mlp", "train.adf_start=5"], 5),
])
def test_the_adf_starts_as_the_patterns_call_for(tiny_scene, tmp_path, overrides, start):
    trainer, _ = loop.prepare(load_config(None, [*TINY, "train.threads=1", *overrides]), tiny_scene, tmp_path)
    t = trainer.cfg.train
    assert trainer.adf_start == {"warmup": t.warmup, "window": t.warmup + t.curriculum}.get(start, start)
    assert trainer.spec_at(trainer.adf_start - 1).adf is False and trainer.spec_at(trainer.adf_start).adf


def test_one_thread_computes_the_aux_losses_inline(tiny_scene, tmp_path):
    trainer, _ = loop.prepare(load_config(None, [*TINY, "train.threads=1"]), tiny_scene, tmp_path)
    assert trainer.aux_worker is None
