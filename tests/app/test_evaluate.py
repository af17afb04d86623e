"""Tests of velogauss/evaluate.py: metric bookkeeping on hand-made predictions and the motion
errors against an analytic scene, with stand-in models whose answers are known exactly."""

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from velogauss import evaluate
from velogauss.data import Camera, Frame
from velogauss.data.cameras import intrinsics_from_fov, look_at
from velogauss.scenes import SCENES
from velogauss_core.constants import ALPHA_MIN, EVAL_SURFACE_MARGIN, SSIM_K1, SSIM_K2

LPIPS_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "lpips"
SIZE = 24  # >= the 11-tap SSIM window


def _camera():
    return Camera(look_at(np.array([0.0, -4.0, 1.0]), np.zeros(3)), intrinsics_from_fov(0.7, SIZE, SIZE), SIZE, SIZE)


def _frame(time, level):
    """A flat frame of the 8-bit `level` (images are kept as 8 bits: spec/data.md), value level / 255."""
    return Frame(np.full((SIZE, SIZE, 3), level, dtype=np.uint8), time, _camera(), f"test/r_{time:.2f}.png")


class ConstantImageModel:
    """Renders a flat grey image whose value is `value_of(t)`."""

    def __init__(self, value_of):
        self.value_of = value_of
        self.calls = []

    def render(self, camera, t, background):
        self.calls.append(t)
        return torch.full((camera.height, camera.width, 3), float(self.value_of(t))), None, {}


def test_identical_images_hit_the_psnr_cap_and_ssim_one(rng):
    image = rng.uniform(size=(SIZE, SIZE, 3)).astype(np.float32)
    row = evaluate.frame_metrics(image, image, with_lpips=False)
    # PSNR_MSE_FLOOR = 1e-10 caps PSNR at exactly 100 dB; SSIM of x with itself is 1
    # (float32 rounding of the local statistics: 1e-5).
    assert row["psnr"] == pytest.approx(100.0, abs=1e-6)
    assert row["ssim"] == pytest.approx(1.0, abs=1e-5)
    assert set(row) == {"psnr", "ssim"}


def test_known_offset_gives_known_psnr_and_ssim():
    gt = np.full((SIZE, SIZE, 3), 0.5, dtype=np.float32)
    row = evaluate.frame_metrics(gt + 0.1, gt, with_lpips=False)
    # MSE = 0.01 -> PSNR = 10 log10(1 / 0.01) = 20 dB; float32 inputs: 1e-4 dB.
    assert row["psnr"] == pytest.approx(20.0, abs=1e-4)
    # Flat images: sigma terms vanish, SSIM = (2 mu_x mu_y + C1) / (mu_x^2 + mu_y^2 + C1).
    c1 = SSIM_K1**2
    assert row["ssim"] == pytest.approx((2 * 0.6 * 0.5 + c1) / (0.36 + 0.25 + c1), abs=1e-5)
    assert SSIM_K2 > 0  # the C2 factor cancels only because it is non-zero


def test_prediction_is_clipped_to_the_image_range():
    gt = np.ones((SIZE, SIZE, 3), dtype=np.float32)
    assert evaluate.frame_metrics(gt + 2.0, gt, with_lpips=False)["psnr"] == pytest.approx(100.0, abs=1e-6)


def test_shape_mismatch_names_pred():
    with pytest.raises(ValueError, match="^pred: "):
        evaluate.frame_metrics(np.zeros((SIZE, SIZE, 3)), np.zeros((SIZE, SIZE + 1, 3)), with_lpips=False)


@pytest.mark.skipif(not (LPIPS_DIR / "alex.npz").is_file(), reason="LPIPS weights not beside the checkout")
def test_lpips_of_identical_images_is_zero(rng):
    image = rng.uniform(size=(32, 32, 3)).astype(np.float32)
    row = evaluate.frame_metrics(image, image, lpips_weights=LPIPS_DIR)
    # Identical feature maps: every squared difference is exactly 0.
    assert row["lpips_alex"] == pytest.approx(0.0, abs=1e-7)
    assert row["lpips_vgg"] == pytest.approx(0.0, abs=1e-7)


def test_mean_over_frames_and_missing_metrics():
    means = evaluate.mean_metrics([{"psnr": 10.0, "ssim": 0.5}, {"psnr": 30.0, "ssim": 1.0}])
    assert means == {"psnr": 20.0, "ssim": 0.75, "lpips_alex": None, "lpips_vgg": None}
    assert evaluate.mean_metrics([]) == dict.fromkeys(evaluate.IMAGE_METRICS)


def test_split_bookkeeping_per_frame_and_mean():
    # Frame k has ground truth 128/255 and prediction 128/255 + d_k: PSNR_k = -20 log10(d_k).
    offsets = {0.1: 0.1, 0.3: 0.01}
    model = ConstantImageModel(lambda t: 128 / 255 + offsets[round(t, 6)])
    frames = [_frame(t, 128) for t in offsets]
    split = evaluate.evaluate_split(model, frames, np.ones(3), name="interpolation")
    assert split["count"] == 2
    assert [r["time"] for r in split["frames"]] == pytest.approx([0.1, 0.3])
    assert [r["path"] for r in split["frames"]] == ["test/r_0.10.png", "test/r_0.30.png"]
    # Float32 images: 1e-3 dB.
    assert [r["psnr"] for r in split["frames"]] == pytest.approx([20.0, 40.0], abs=1e-3)
    assert split["mean"]["psnr"] == pytest.approx(30.0, abs=1e-3)


def test_freeze_baseline_renders_at_max_time():
    model = ConstantImageModel(lambda t: t)  # brightness = time: a perfect "motion" model
    frames = [_frame(204 / 255, 204), _frame(230 / 255, 230)]  # times 0.8 and 0.902, brightness = time
    base = evaluate.freeze_baseline(model, frames, np.ones(3), max_time=0.75)
    assert model.calls == [0.75, 0.75]
    # Frozen at 0.75: errors 0.05 and 230/255 - 0.75 -> PSNR 26.0206 and 16.3659 dB.
    expected = [-20 * math.log10(0.05), -20 * math.log10(230 / 255 - 0.75)]
    assert [r["psnr"] for r in base["frames"]] == pytest.approx(expected, abs=1e-3)
    assert base["mean"]["psnr"] == pytest.approx(np.mean(expected), abs=1e-3)
    own = evaluate.evaluate_split(model, frames, np.ones(3), name="extrapolation")
    assert own["mean"]["psnr"] == pytest.approx(100.0, abs=1e-3)


def test_background_baseline_scores_an_empty_render():
    # Frames of uniform brightness 204/255 and 230/255 against a white background (1): errors
    # 51/255 = 0.2 and 25/255 -> PSNR 13.9794 and 20.1720 dB; a frame that is the background scores 100.
    frames = [_frame(204 / 255, 204), _frame(230 / 255, 230), _frame(1.0, 255)]
    base = evaluate.background_baseline(frames, np.ones(3))
    expected = [-20 * math.log10(51 / 255), -20 * math.log10(25 / 255), 100.0]
    assert base["count"] == 3 and [r["psnr"] for r in base["frames"]] == pytest.approx(expected, abs=1e-3)
    assert base["mean"]["psnr"] == pytest.approx(np.mean(expected), abs=1e-3)
    assert base["frames"][2]["ssim"] == pytest.approx(1.0)


class VelocityModel:
    """Stand-in motion model: particle velocity `scale · v_true` of the material point that
    started at x0 (computed from x0, so a wrong start shows), Eulerian field
    `field_scale · v_true` (default `scale`); tracked positions `mu0`, or the true paths
    from `mu0` with `exact_paths`; `has_velocity` False mimics deform-only."""

    def __init__(self, scene, scale=1.0, mu0=None, opacity=None, exact_paths=False, has_velocity=True,
                 field_scale=None):
        self.scene, self.scale, self.has_velocity = scene, scale, has_velocity
        self.field_scale = scale if field_scale is None else field_scale
        self.mu0 = mu0 if mu0 is not None else np.zeros((1, 3))
        self.opacity = opacity if opacity is not None else np.ones(len(self.mu0))
        self.exact_paths = exact_paths

    def velocity_at(self, x, t):
        return torch.as_tensor(self.field_scale * self.scene.velocity(x.double().numpy(), t, margin=np.inf))

    def particle_velocity(self, x0, x, t):
        at = self.scene.position(x0.double().numpy(), t, margin=np.inf)
        return torch.as_tensor(self.scale * self.scene.velocity(at, t, margin=np.inf))

    def tracked_positions(self, t):
        if self.exact_paths:
            return torch.as_tensor(self.scene.position(self.mu0, t, margin=EVAL_SURFACE_MARGIN))
        return torch.as_tensor(self.mu0)

    def render_inputs_at(self, t):
        return {"opacities": torch.as_tensor(self.opacity)}


@pytest.mark.parametrize("scale, expected", [(1.0, 0.0), (0.0, 1.0), (2.0, 1.0), (1.5, 0.5)])
def test_velocity_relative_error_of_scaled_fields(scale, expected):
    scene = SCENES["toss"]()
    error = evaluate.velocity_error(VelocityModel(scene, scale), scene, max_time=0.75)
    assert error["points"] == evaluate.MOTION_EVAL_POINTS  # one moving body: every sample kept
    # ‖(s − 1) v‖ / ‖v‖ = |s − 1| exactly; float32 queries: 1e-6.
    for group in ("observed", "future", "all"):
        assert error[group]["relative_l2"] == pytest.approx(expected, abs=1e-6)
        assert error[group]["field_relative_l2"] == pytest.approx(expected, abs=1e-6)
    assert [r["time"] for r in error["per_time"]] == pytest.approx(np.linspace(0, 1, 11))
    assert len([r for r in error["per_time"] if r["time"] > 0.75]) == 3  # 0.8, 0.9, 1.0


def test_a_reversal_has_no_relative_error_instead_of_dividing_by_rounding():
    # pulse's strain rate is cos(3 pi t): at t = 0.5 it is zero up to rounding (~1e-16), and
    # a model off by a zero velocity of 1e-3 must not score 1e13 there.
    scene = SCENES["pulse"]()
    error = evaluate.velocity_error(VelocityModel(scene, scale=0.5), scene, max_time=0.75)
    at_half = [r for r in error["per_time"] if r["time"] == pytest.approx(0.5)][0]
    assert at_half["relative_l2"] is None and at_half["mean_abs"] is not None
    assert error["observed"]["relative_l2"] == pytest.approx(0.5, abs=1e-6)
    assert sum(r["relative_l2"] is None for r in error["per_time"]) == 1


def test_particle_velocity_and_eulerian_field_are_scored_apart():
    scene = SCENES["toss"]()
    error = evaluate.velocity_error(VelocityModel(scene, scale=1.0, field_scale=0.0), scene, max_time=0.75)
    assert error["all"]["relative_l2"] == pytest.approx(0.0, abs=1e-6)
    assert error["all"]["field_relative_l2"] == pytest.approx(1.0, abs=1e-6)


def test_a_model_without_velocity_field_has_no_velocity_error():
    scene = SCENES["toss"]()
    error = evaluate.velocity_error(VelocityModel(scene, has_velocity=False), scene, max_time=0.75)
    assert all(r["relative_l2"] is None and r["mean_abs"] is None for r in error["per_time"])
    assert error["all"] == dict.fromkeys(evaluate.VELOCITY_KEYS)


class OffsetVelocityModel(VelocityModel):
    """The true particle velocity plus `offset(x (M, 3), t) -> (M, 3)`, at the points' true positions x."""

    def __init__(self, scene, offset):
        super().__init__(scene)
        self.offset = offset

    def particle_velocity(self, x0, x, t):
        return super().particle_velocity(x0, x, t) + torch.as_tensor(self.offset(x.double().numpy(), t))


def _true_velocities(scene, points, t):
    x = scene.position(points, t, margin=np.inf)
    return x, scene.velocity(x, t, margin=np.inf)


def test_a_velocity_error_common_to_the_body_is_all_translation():
    scene = SCENES["toss"]()
    points = evaluate.moving_surface_points(scene)
    c = np.array([0.3, -0.2, 0.1])
    error = evaluate.velocity_error(OffsetVelocityModel(scene, lambda x, t: np.broadcast_to(c, x.shape)), scene,
                                    max_time=0.75, points=points)
    for row in error["per_time"]:
        _, v = _true_velocities(scene, points, row["time"])
        expected = math.sqrt(len(points)) * np.linalg.norm(c) / np.linalg.norm(v)
        # float32 queries: 1e-6 relative.
        assert row["relative_l2"] == pytest.approx(expected, rel=1e-5)
        assert row["translation_relative_l2"] == pytest.approx(expected, rel=1e-5)
        assert row["spin_relative_l2"] == pytest.approx(0.0, abs=1e-5)


def test_a_spin_about_the_points_centre_is_no_translation():
    scene = SCENES["toss"]()
    points = evaluate.moving_surface_points(scene)
    omega = np.array([0.0, 0.5, 2.0])

    def spin(x, t):
        centre = scene.position(points, t, margin=np.inf).mean(axis=0)  # the points' mean at t
        return np.cross(omega, x - centre)

    error = evaluate.velocity_error(OffsetVelocityModel(scene, spin), scene, max_time=0.75, points=points)
    for row in error["per_time"]:
        x, v = _true_velocities(scene, points, row["time"])
        expected = np.linalg.norm(np.cross(omega, x - x.mean(axis=0))) / np.linalg.norm(v)
        assert row["spin_relative_l2"] == pytest.approx(expected, rel=1e-5)
        assert row["relative_l2"] == pytest.approx(expected, rel=1e-5)
        assert row["translation_relative_l2"] == pytest.approx(0.0, abs=1e-5)


def test_the_two_parts_add_up_in_squares():
    scene = SCENES["multi"]()
    error = evaluate.velocity_error(VelocityModel(scene, scale=0.6), scene, max_time=0.75)
    for row in error["per_time"]:
        if row["relative_l2"] is not None:
            assert row["translation_relative_l2"] ** 2 + row["spin_relative_l2"] ** 2 == pytest.approx(
                row["relative_l2"] ** 2, rel=1e-6)


def test_translation_only_is_the_true_motion_less_each_body_s_mean():
    # multi has three moving bodies (and a still ground, whose points are dropped): one mean over
    # them would differ from a mean per body.
    scene = SCENES["multi"]()
    points = evaluate.moving_surface_points(scene)
    owner = scene.body_index(points, 0.0, margin=np.inf)
    assert len(np.unique(owner)) == 3
    error = evaluate.velocity_error(VelocityModel(scene), scene, max_time=0.75, points=points)
    compared = 0
    for row in error["per_time"]:
        _, v = _true_velocities(scene, points, row["time"])
        if row["relative_l2"] is None:
            continue
        rest = v.copy()
        for body in np.unique(owner):
            rest[owner == body] -= v[owner == body].mean(axis=0)
        assert row["translation_only_relative_l2"] == pytest.approx(np.linalg.norm(rest) / np.linalg.norm(v),
                                                                    rel=1e-9)
        compared += 1
    assert compared >= 10


def _one_box(motion):
    from velogauss.scenes.bodies import Body, Texture
    from velogauss.scenes.scene import AnalyticScene
    box = Body("box", "box", np.array([0.2, -0.1, 0.3]), np.array([0.3, 0.2, 0.25]), np.eye(3),
               Texture("checker", ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)), frequency=2.0), motion)
    return AnalyticScene("box", [box], ("translation", "rotation"), True)


def test_the_true_motion_scores_zero_and_a_glide_needs_no_spin():
    from velogauss.scenes.trajectories import RigidMotion
    scene = _one_box(RigidMotion([0.2, -0.1, 0.3], velocity=[1.0, 0.5, 0.0], gravity=[0.0, 0.0, -2.0]))
    error = evaluate.velocity_error(evaluate.TrueMotion(scene), scene, max_time=0.75)
    for group in ("observed", "future"):
        assert error[group]["relative_l2"] == pytest.approx(0.0, abs=1e-6)  # float32 queries
        assert error[group]["translation_only_relative_l2"] == pytest.approx(0.0, abs=1e-12)


def test_a_spin_in_place_is_all_beyond_translation():
    from velogauss.scenes.trajectories import RigidMotion
    centre, omega = np.array([0.2, -0.1, 0.3]), np.array([0.0, 0.0, 3.0])
    scene = _one_box(RigidMotion(centre, omega=omega))
    points = evaluate.moving_surface_points(scene)
    error = evaluate.velocity_error(evaluate.TrueMotion(scene), scene, max_time=0.75, points=points)
    for row in error["per_time"]:
        x = scene.position(points, row["time"], margin=np.inf)
        # v = ω × (x − c); its mean over the points is ω × (x̄ − c), not quite zero for a sample.
        expected = np.linalg.norm(np.cross(omega, x - x.mean(axis=0))) / np.linalg.norm(np.cross(omega, x - centre))
        assert row["translation_only_relative_l2"] == pytest.approx(expected, rel=1e-9)
        assert expected > 0.99


def test_velocity_points_skip_static_bodies():
    scene = SCENES["multi"]()
    points = evaluate.moving_surface_points(scene)
    owner = scene.body_index(points, 0.0, margin=np.inf)
    assert 0 < len(points) < evaluate.MOTION_EVAL_POINTS
    assert "ground" not in {scene.bodies[k].name for k in owner}


def test_trajectory_selection_and_errors():
    scene = SCENES["toss"]()  # one box centred at (-0.5, 0, -0.5) at t = 0
    box = scene.bodies[0]
    centre = np.asarray(box.centre)
    mu0 = np.array([
        centre,                                          # inside: kept
        centre + [0.0, 0.0, box.size.max() + 1.0],       # far outside: dropped
        centre + [0.01, 0.0, 0.0],                       # inside but nearly transparent: dropped
    ])
    opacity = np.array([1.0, 1.0, 0.5 * ALPHA_MIN])
    exact = evaluate.trajectory_error(VelocityModel(scene, mu0=mu0, opacity=opacity, exact_paths=True), scene, 0.75)
    frozen = evaluate.trajectory_error(VelocityModel(scene, mu0=mu0, opacity=opacity), scene, 0.75)
    deform_only = evaluate.trajectory_error(
        VelocityModel(scene, mu0=mu0, opacity=opacity, exact_paths=True, has_velocity=False), scene, 0.75)
    assert deform_only["all"]["mean_distance"] == pytest.approx(0.0, abs=1e-12)
    assert exact["gaussians"] == frozen["gaussians"] == 1
    assert exact["all"]["mean_distance"] == pytest.approx(0.0, abs=1e-12)
    # A model that does not move scores exactly the "nothing moved" reference distance,
    # which for the thrown box's centre is |c(t) − c(0)|.
    for row in frozen["per_time"]:
        assert row["mean_distance"] == pytest.approx(row["static_mean_distance"], abs=1e-12)
        t = row["time"]
        shift = box.motion.velocity0 * t + 0.5 * box.motion.gravity * t * t
        assert row["mean_distance"] == pytest.approx(np.linalg.norm(shift), abs=1e-12)


def test_no_selected_gaussian_gives_none():
    scene = SCENES["toss"]()
    far = np.array([[10.0, 10.0, 10.0]])
    error = evaluate.trajectory_error(VelocityModel(scene, mu0=far), scene, 0.75)
    assert error["gaussians"] == 0
    assert error["all"]["mean_distance"] is None


def test_unknown_split_is_named():
    with pytest.raises(ValueError, match="^splits: "):
        evaluate.evaluate_model(None, None, splits=("future",))


def test_markdown_tables():
    result = {
        "max_time": 0.75,
        "splits": {"interpolation": {"count": 1, "mean": {"psnr": 31.234, "ssim": 0.95, "lpips_alex": None,
                                                            "lpips_vgg": None},
                                     "frames": [{"path": "val/a.png", "time": 0.5, "psnr": 31.234, "ssim": 0.95}]}},
        "freeze_baseline": None, "motion": None,
    }
    text = evaluate.metrics_markdown(result)
    assert "| interpolation (t ≤ 0.75) | 1 | 31.23 | 0.9500 | — | — |" in text
    assert "empty render" not in text  # results written before the empty-render baseline still read
    result["background_baseline"] = {"interpolation": {"count": 1, "mean": {"psnr": 28.176, "ssim": 0.9}}}
    assert ("| interpolation, baseline: an empty render (the background alone) | 1 | 28.18 | 0.9000 | — | — |"
            in evaluate.metrics_markdown(result))
    assert "| val/a.png | 0.500 | 31.23 | 0.9500 | — | — |" in text


def test_lpips_is_skipped_with_a_note_when_no_default_weights_exist(monkeypatch):
    def nowhere(net, weights_dir=None):
        raise FileNotFoundError(2, f"LPIPS weights {net}.npz not found and the download failed", f"{net}.npz")

    monkeypatch.setattr(evaluate, "weights_file", nowhere)
    usable, note = evaluate.lpips_status()
    assert not usable and note.startswith("skipped: LPIPS weights alex.npz not found")
    model = ConstantImageModel(lambda t: 128 / 255 + 0.1)
    split = evaluate.evaluate_split(model, [_frame(0.1, 128)], np.ones(3), name="interpolation")
    assert set(split["frames"][0]) == {"path", "time", "psnr", "ssim"}
    assert split["mean"]["lpips_alex"] is None and split["mean"]["psnr"] == pytest.approx(20.0, abs=1e-3)


def test_an_explicit_lpips_folder_must_hold_the_weights(tmp_path):
    assert evaluate.lpips_status(tmp_path) == (True, str(tmp_path))
    model = ConstantImageModel(lambda t: 0.6)
    frame = _frame(0.1, 128)
    with pytest.raises(FileNotFoundError, match="weights_dir: LPIPS weights"):
        evaluate.evaluate_split(model, [frame], np.ones(3), lpips_weights=tmp_path)
