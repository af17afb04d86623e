"""The training loop: a few views of one time per iteration, photometric + physics losses,
density control.

Per iteration (velogauss.config holds every number):
1. draw a training frame by the time curriculum, with up to `train.views - 1` other cameras
   of its time (velogauss.train.sampling);
2. move the Gaussians to that time once (VG-TRAJ + VG-ADF) and render each view (VG-RENDER);
3. loss = photometric (VG-LOSS, the mean over the views) + ramped physics loss (VG-LOSS-PHYS) on collocation
   points at a random time in [0, 1] + lambda_adf · mean |Δx|² (the ADF stays a residual)
   + the mixing weights' entropy (VG-LOSS-MIX: each particle commits to one motion pattern);
   the auxiliary losses, which no render goes through (physics, VG-LOSS-CARRY, mixing), run
   in a worker process beside the renders (velogauss.train.aux_losses,
   velogauss.train.aux_worker), and the ADF's backward in a thread beside the integration's
   (velogauss.train.adf_backward_thread);
4. Adam step with the scheduled learning rates; density statistics; every
   `densify.every` iterations clone/split/prune, opacity resets (each followed by at least a
   reset period of training), static-particle detection.
A progress bar shows loss, PSNR and the Gaussian count; every `eval_every` iterations the
PSNR on the interpolation split goes to `RUN_DIR/log.jsonl`; checkpoints are atomic and
resuming from one continues exactly where it stopped (same draws, same numbers). Ctrl-C
finishes the current iteration, writes a checkpoint and stops.
"""

import contextlib
import dataclasses
import json
import signal
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from tqdm.auto import tqdm

from velogauss.config import (check_resume_config, config_from_dict, resolve_from_run, resolve_schedule,
                              resolve_transport, to_toml)
from velogauss.data import check_trainable_size
from velogauss.io_utils import write_text
from velogauss.memory import peak_rss_mib
from velogauss.model import build_model, model_from_state, scene_spec
from velogauss.model.velogauss_model import moving_state_at, render_gaussians
from velogauss.provenance import record_session
from velogauss.threads import apply_threads
from velogauss.train.checkpoint import (checkpoint_path, forecast_spec, load_checkpoint, remove_stale_temporaries,
                                       save_checkpoint)
from velogauss.train.forecast import fit_forecast, needs_forecast
from velogauss.train.densify import DensityStats, densify_and_prune, reset_opacity, torch_generator
from velogauss.train.backtest import choose_form, selects_form
from velogauss.train.centres import anchor_centres, first_knot_mask, resolve_rigid_centre
from velogauss.train.frequency import start_frequency
from velogauss.train.mixing import place_patterns, resolve_mixing_init
from velogauss.train.optim import make_optimizer, set_learning_rates
from velogauss.train import aux_losses, aux_worker
from velogauss.train.adf_backward_thread import adf_evaluation
from velogauss.train.sampling import FrameSampler, auto_iterations, camera_extent
from velogauss.train.static import detect_moving, pixel_footprint
from velogauss.train.targets import TrainingTargets
from velogauss_fast.backends import numba_backend
from velogauss_fast.losses import photometric_loss
from velogauss_fast.metrics import psnr
from velogauss_core.constants import STATIC_MOTION_PX
from velogauss_core.motion import spec_from_dict

# Frames of the interpolation split scored at each evaluation (evenly spread): enough for
# a stable mean, few enough that an evaluation costs a fraction of a second.
_EVAL_FRAMES = 8
# Smoothing of the PSNR shown in the progress bar (exponential moving average weight).
_PSNR_EMA = 0.9


def train(cfg, data, run_dir, resume=False, progress=True, frequency=None):
    """Train a VeloGauss model on `data` (velogauss.data.SceneData); return it in eval mode.

    cfg: velogauss.config.Config; run_dir: the run folder (config.toml, checkpoints/,
    log.jsonl); resume: continue from `run_dir`'s latest checkpoint (the config must match
    the one it was trained with, except `train.iterations`, which may grow). Sets torch's and
    the compositing kernels' CPU threads from `train.threads` (velogauss.threads). frequency:
    where the video gives none, the start of a new run's harmonic patterns (the backtest's probe
    of a form passes its paths' frequency; velogauss.train.frequency.start_frequency).
    """
    trainer, start = prepare(cfg, data, run_dir, resume, progress, frequency)
    trainer.run(start, progress)
    return trainer.model.eval()


def warn_short_schedule(train_cfg):
    """Warn (UserWarning naming the keys) when fewer iterations train on the whole observed
    window than the curriculum took to open it: such a run undertrains the motion
    (benchmarks/FIDELITY.md, section 4). The "auto" schedule never warns. A warning, not an
    error: short runs are legitimate for tests and quick looks. `train_cfg`: a resolved
    `TrainConfig` (config.resolve_schedule)."""
    opened = train_cfg.warmup + train_cfg.curriculum
    left = train_cfg.iterations - opened
    if train_cfg.curriculum and left < train_cfg.curriculum:
        warnings.warn(
            f"train.iterations = {train_cfg.iterations}: the time window opens fully at iteration {opened} "
            f"(train.warmup + train.curriculum), leaving {max(left, 0)} iterations on the whole window, fewer "
            f"than the curriculum's {train_cfg.curriculum}; the motion will be undertrained. Lower "
            f"train.curriculum (and densify.until) with train.iterations, or leave them \"auto\" to scale "
            f"with it.", UserWarning, stacklevel=3)


def prepare(cfg, data, run_dir, resume=False, progress=False, frequency=None):
    """The training state of `train` before its first iteration: (Trainer, first iteration).

    Writes config.toml and an empty log.jsonl into `run_dir` for a new run, and the session into
    its provenance.json (velogauss.provenance) for a new run or a resumed one; `trainer.step(it)`
    and `trainer.adapt_gaussians(it + 1)` then run iteration `it` (the contention benchmark
    times them).
    The "auto" keys of the run's length, its schedule and the transport weight are resolved here
    (`auto_iterations`, `resolve_schedule`, `resolve_transport`): for a new run from the
    training frames' times, `train.iterations` and the
    motion patterns of the scene's spec, on resume to the run's own values; `trainer.cfg` and config.toml
    hold the numbers used. `cfg.data.max_time` becomes the loaded scene's `max_time`: under a
    "future:F" `cfg.data.split` the window's end that split derived, under "time" a generated
    scene's own where the config left the default (spec/data.md, "Splits"); `cfg.data.background`
    likewise becomes a generated scene's own background.
    """
    _, parallel = apply_threads(cfg.train.threads)
    check_trainable_size(data)
    # The window's end and the background may come from the data; config.toml records them.
    own = {"max_time": data.max_time}
    if not np.allclose(data.background, cfg.data.background):  # else a float32 copy of the config's
        own["background"] = tuple(float(v) for v in data.background)
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, **own))
    run_dir = Path(run_dir)
    device = torch.device(cfg.train.device)
    extent = camera_extent([f.camera for f in data.train])
    remove_stale_temporaries(run_dir)
    if resume:
        payload = load_checkpoint(run_dir, device)
        saved = config_from_dict(payload["config"], str(checkpoint_path(run_dir)))
        cfg = resolve_from_run(cfg, saved)
        check_resume_config(saved, cfg)
        model = model_from_state(cfg, spec_from_dict(payload["spec"]), payload["model"], forecast_spec(payload))
        model.load_state_dict(payload["model"])
        model.to(device)
        rng = np.random.default_rng()
        rng.bit_generator.state = payload["numpy_rng"]
        torch.set_rng_state(payload["torch_rng"])
        start, state = payload["iteration"], RunState(**payload["extra"])
        if cfg.model.future == "fit" and start < cfg.train.iterations:
            # More training moves the paths: the forecast is fitted again at the new end.
            model.set_forecast(None)
            model.spec = dataclasses.replace(model.spec, future="fit")
        _truncate_log(run_dir / "log.jsonl", start)
        # The checkpoint and config.toml stay one truth: the changes check_resume_config allows.
        write_text(run_dir / "config.toml", to_toml(cfg))
    else:
        if cfg.train.iterations == "auto":
            iterations = auto_iterations([f.time for f in data.train], cfg.train.views,
                                         scene_spec(cfg, data.metadata).moving)
            cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, iterations=iterations))
        # model.patterns "auto": a short probe's Gaussian paths choose the form (and the mixing's start).
        report = None
        if selects_form(cfg):
            cfg, report = choose_form(cfg, data, train, progress)
        cfg = resolve_schedule(cfg)
        warn_short_schedule(cfg.train)
        rng = np.random.default_rng(cfg.train.seed)
        torch.manual_seed(cfg.train.seed)
        spec = scene_spec(cfg, data.metadata)
        cfg = resolve_transport(cfg, spec.pattern_form)
        points, colors = _initial_points(data, cfg.model.init_points, rng)
        model = build_model(cfg, spec, points, colors, rng).to(device)
        if model.spec.velocity == "affine":
            place_patterns(model.motion, model.gaussians.means, rng, resolve_mixing_init(cfg.model.mixing_init, spec),
                           cfg.model.pattern_centres)
        start_frequency(model, data.train, data.max_time, frequency if report is None else report["frequency"])
        start, state = 0, RunState()
        run_dir.mkdir(parents=True, exist_ok=True)
        if report is not None:
            write_text(run_dir / "motion_form.json", json.dumps(report, indent=1))
        write_text(run_dir / "config.toml", to_toml(cfg))
        write_text(run_dir / "log.jsonl", "")
    record_session(run_dir, start)
    optimizer = make_optimizer(model, cfg.train, extent)
    stats = DensityStats(len(model.gaussians), device=device)
    if resume:
        optimizer.load_state_dict(payload["optimizer"])
        stats.load_state_dict(payload["density"])
    # The auxiliary losses go to a worker process where the thread budget allows two parallel
    # parts (the compositing's), on the CPU only, whose cores the split shares; elsewhere they
    # run inline. Started now (once per process), so that it has imported torch by the end of
    # the warm-up, which has no auxiliary losses.
    worker = aux_worker.process() if parallel >= 2 and device.type == "cpu" else None
    return Trainer(cfg, data, run_dir, model, optimizer, stats, rng, extent, state, device, worker), start


@dataclasses.dataclass
class RunState:
    """What a run carries from iteration to iteration besides the model, the optimiser, the
    density statistics and the RNGs; checkpoints hold it (as a dict, key "extra"), so that a
    resumed run continues as an uninterrupted one."""

    elapsed_s: float = 0.0  # training time of the run's sessions so far
    after_reset: bool = False  # an opacity reset has happened: densification then prunes by size too
    psnr_ema: float | None = None  # the progress bar's moving average of the PSNR, None before the first step


class Trainer:
    """The state of one training run between iterations: `step` runs one, `adapt_gaussians`
    then adapts the set of Gaussians, `run` loops both with logging and checkpoints."""

    def __init__(self, cfg, data, run_dir, model, optimizer, stats, rng, extent, state, device, aux_worker):
        self.cfg, self.data, self.run_dir = cfg, data, run_dir
        # velogauss.train.aux_worker.AuxWorker: the auxiliary losses beside the renders, or None (inline).
        self.aux_worker = aux_worker
        self.model, self.optimizer, self.stats = model, optimizer, stats
        self.rng, self.extent, self.state, self.device = rng, extent, state, device
        # What the motion computes and which losses are on, resolved once when the model was built.
        self.spec = model.spec
        # The images and their halves of SSIM, kept between steps within a memory budget.
        self.targets = TrainingTargets(data.train, device)
        # The distinct training cameras (multi-view video repeats each pose at every time).
        self.cameras = list({(f.camera.viewmat.tobytes(), f.camera.K.tobytes()): f.camera for f in data.train}.values())
        self.sampler = FrameSampler([f.time for f in data.train], cfg.train.warmup, cfg.train.curriculum,
                                    self.spec.moving, cfg.train.views, cfg.train.warmup_views)
        self.background = torch.as_tensor(data.background, dtype=torch.float32, device=device)
        self.eval_frames = _spread(data.interpolation, _EVAL_FRAMES)
        self.adf_start = cfg.train.adf_start if cfg.train.adf_start != "auto" else self.auto_adf_start()
        # Rigid patterns anchored on the body's centre (velogauss.train.centres): the mask that
        # holds their first knot from the warm-up's end, None when the centres are learned.
        anchored = (self.spec.velocity == "affine" and
                    resolve_rigid_centre(cfg.model.rigid_centre, self.spec, cfg.model.mixing_init) == "hull")
        self.knot_mask = first_knot_mask(model.motion.time.detach()) if anchored else None

    def auto_adf_start(self):
        """`train.adf_start = "auto"`: the warm-up's end where the ADF is (part of) the motion
        from the start (deform-only, which has no velocity; scheme "adf-step", whose window the
        ADF carries; the time network's patterns, whose deformations it refines), else the
        curriculum's end, so that rigid and oscillating patterns, not the ADF, learn the motion
        (benchmarks/FIDELITY.md, section 0f)."""
        spec, t = self.spec, self.cfg.train
        adf_first = (spec.velocity is None or spec.scheme == "adf-step"
                     or (spec.velocity == "affine" and spec.pattern_form == "mlp"))
        return t.warmup if adf_first else t.warmup + t.curriculum

    def run(self, start, progress):
        cfg = self.cfg.train
        bar = tqdm(range(start, cfg.iterations), initial=start, total=cfg.iterations, disable=not progress,
                   desc="train", dynamic_ncols=True)
        # The moving average goes into checkpoints (RunState), so a resumed run logs what an
        # uninterrupted one does.
        psnr_ema, loss_value = self.state.psnr_ema, float("nan")
        # Training time of earlier sessions of this run (resume) plus this session's.
        elapsed_before, clock = self.state.elapsed_s, time.perf_counter()
        with _deferred_interrupt() as interrupted:
            for it in bar:
                loss_value, frame_psnr = self.step(it)
                psnr_ema = frame_psnr if psnr_ema is None else _PSNR_EMA * psnr_ema + (1 - _PSNR_EMA) * frame_psnr
                done = it + 1
                self.adapt_gaussians(done)
                bar.set_postfix(loss=f"{loss_value:.4f}", psnr=f"{psnr_ema:.2f}", n=len(self.model.gaussians),
                                refresh=False)
                elapsed = elapsed_before + time.perf_counter() - clock
                if cfg.eval_every and (done % cfg.eval_every == 0 or done == cfg.iterations):
                    self.log_eval(done, loss_value, psnr_ema, elapsed)
                last = done == cfg.iterations
                if last and not interrupted() and needs_forecast(self.model):
                    self.fit_forecast()
                if interrupted() or last or (cfg.checkpoint_every and done % cfg.checkpoint_every == 0):
                    self.state.psnr_ema = psnr_ema
                    self.checkpoint(done, elapsed)
                if interrupted():
                    bar.close()
                    raise KeyboardInterrupt(f"training interrupted; checkpoint at iteration {done} in {self.run_dir}")
        if start >= cfg.iterations:
            bar.close()

    def step(self, it):
        """One optimisation step; returns (loss, PSNR of the first rendered view).

        The auxiliary losses (physics, carry, mixing: velogauss.train.aux_losses) are drawn
        first and computed beside the renders; their gradients join the renders' after its
        backward."""
        cfg, model = self.cfg, self.model
        set_learning_rates(self.optimizer, it, cfg.train, self.extent)
        indices = self.sampler.sample_views(it, self.rng, cfg.train.views)
        frames = [self.data.train[i] for i in indices]
        spec = self.spec_at(it)
        motion_on = spec.moving and it >= cfg.train.warmup
        params = None
        if spec.moving:
            self.freeze_motion(it)
            if it == cfg.train.warmup and self.knot_mask is not None:
                anchor_centres(model)  # the patterns are still until now: the motion does not change
            params = model.motion.params()  # once per step: the render and the auxiliary losses share it
        offset = self.carry_offset(it, spec)
        self.optimizer.zero_grad(set_to_none=True)
        draws = aux_losses.draw(cfg, model, spec, it, self.rng, self.data.bounds, self.sampler.window(it),
                                self.device)
        pending = aux_losses.start(model, cfg, params, spec, draws, self.aux_worker)
        try:
            with self.render_threads():
                loss, renders = self.render_loss(frames, indices, params, spec, offset, motion_on)
            loss.backward()
        finally:
            aux_value = aux_losses.finish(pending)  # waits for the worker even when the renders raised
        for _, meta, camera in renders:
            grad = meta["mean2d"].grad
            if grad is not None:
                # Each view's loss is weighted 1/len(frames); densification compares a view's
                # own pixel gradient with its threshold, whatever the number of views per step.
                self.stats.add(grad.detach() * len(frames), meta["radius"], meta["valid"], camera.width,
                               camera.height)
        if self.knot_mask is not None and it >= cfg.train.warmup and model.motion.time.grad is not None:
            model.motion.time.grad.mul_(self.knot_mask)  # the centre anchored at the warm-up's end stays put
        self.optimizer.step()
        with torch.no_grad():
            image = renders[0][0]
            frame_psnr = float(psnr(image.detach().clamp(0, 1), self.targets.image(indices[0])))
        return float(loss.detach()) + aux_value, frame_psnr

    def render_threads(self):
        """The compositing threads of the step's renders (a context): with the auxiliary losses'
        worker, one fewer than the run's, at least one, so that the worker keeps a core while
        the views render (benchmarks/RESULTS.md, "Toward a 2x step"); the numbers do not change."""
        if self.aux_worker is None:
            return contextlib.nullcontext()
        return numba_backend.num_threads(max(1, numba_backend.get_num_threads() - 1))

    def render_loss(self, frames, indices, params, spec, offset, motion_on):
        """(photometric loss over the views + the ADF's lambda_adf · mean |Δx|², [(image,
        meta, camera)] of each view): one state for all the views, which show one time."""
        model, g = self.model, self.model.gaussians
        # The ADF's backward in a thread beside the integration's where the auxiliary losses
        # have a worker too, as both need the same second core.
        adf = adf_evaluation(spec) if self.aux_worker is not None else None
        means, quats, scales, base = moving_state_at(params, spec, g.means, g.quats, g.scales, model.moving,
                                                     frames[0].time, offset, adf)
        gaussians = model.with_appearance(means, quats, scales)
        renders, loss = [], 0.0
        for frame, index in zip(frames, indices):
            image, _, meta = render_gaussians(gaussians, frame.camera, self.background)
            if meta["mean2d"].requires_grad:  # not when nothing trainable moves them (train.motion_only)
                meta["mean2d"].retain_grad()
            loss = loss + photometric_loss(image, *self.targets[index]) / len(frames)
            renders.append((image, meta, frame.camera))
        if motion_on and self.spec.adf_loss:
            loss = loss + self.cfg.train.lambda_adf * ((means - base) ** 2).sum(1).mean()
        return loss, renders

    def spec_at(self, it):
        """The model's spec at iteration `it`: without the ADF before `adf_start` (its last
        layer is still zero, so skipping it is exactly the identity, and cheaper)."""
        return self.spec if not self.spec.adf or it >= self.adf_start else self.spec.without_adf()

    def freeze_motion(self, it):
        """Motion networks train from the warm-up's end, the ADF from `adf_start` (by default
        with them under the time network's patterns, else once the curriculum has opened the
        whole window, so that the velocity, not the ADF, learns the motion; the ADF then
        refines what the affine velocity cannot represent).

        Frozen parameters get no gradient at all: a zero gradient would still advance Adam's
        step count, and its bias correction would later inflate their first real updates.
        """
        motion = self.model.motion
        t = self.cfg.train
        motion.requires_grad_(it >= t.warmup)
        if t.motion_only:
            self.model.gaussians.requires_grad_(it < t.warmup)
        if self.spec.adf:
            motion.adf.requires_grad_(it >= self.adf_start)

    def carry_offset(self, it, spec):
        """Scheme "adf-step": the signed step ±spec.carry_offset of VG-CARRY, a fair coin per
        iteration once the motion trains (the authors' released code); else 0."""
        if spec.scheme != "adf-step" or it < self.cfg.train.warmup:
            return 0.0
        return spec.carry_offset * (1.0 if self.rng.random() < 0.5 else -1.0)

    def adapt_gaussians(self, done):
        """The density control (densify and prune), opacity resets and static-particle detection
        due after `done` iterations (the ADF as the next iteration will run it)."""
        d, model = self.cfg.densify, self.model
        if d.start < done <= d.until and done % d.every == 0:
            densify_and_prune(model, self.optimizer, self.stats, d, self.extent,
                              max(self.data.width, self.data.height), self.state.after_reset,
                              torch_generator(self.rng), done)
        # A reset with less than one reset period left would end the run on faded Gaussians,
        # so it is skipped, as 3DGS resets only long before its end.
        recovers = self.cfg.train.iterations - done >= d.opacity_reset_every
        if d.opacity_reset_every and done % d.opacity_reset_every == 0 and done <= d.until and recovers:
            reset_opacity(model, self.optimizer)
            self.state.after_reset = True
        window_open = done >= self.cfg.train.warmup + self.cfg.train.curriculum
        if self.spec.moving and d.static_every and window_open and done % d.static_every == 0:
            with torch.no_grad():
                threshold = STATIC_MOTION_PX * pixel_footprint(model.gaussians.means, self.cameras)
            model.set_moving(detect_moving(model, self.cfg.data.max_time, threshold, self.spec_at(done - 1)))

    def log_eval(self, done, loss_value, train_psnr, elapsed):
        """Append one evaluation record to log.jsonl (`peak_rss_mib`: the process's peak resident
        memory so far, which under `velogauss sweep` is the run's own, one process a run)."""
        with torch.no_grad():
            spec = self.spec_at(done - 1)
            scores = [float(psnr(self.model.render(f.camera, f.time, self.background, spec)[0].clamp(0, 1),
                                 torch.as_tensor(f.image, device=self.device))) for f in self.eval_frames]
        record = {"iteration": done, "loss": loss_value, "train_psnr": train_psnr,
                  "interp_psnr": float(np.mean(scores)) if scores else None,
                  "n_gaussians": len(self.model.gaussians), "n_moving": int(self.model.moving.sum()),
                  "elapsed_s": round(elapsed, 3), "peak_rss_mib": peak_rss_mib()}
        with open(self.run_dir / "log.jsonl", "a") as handle:
            handle.write(json.dumps(record) + "\n")

    def fit_forecast(self):
        """The future of a model whose spec says "fit", from its trained paths (velogauss.train.forecast),
        with its own generator so that the run's draws stay those of an uninterrupted run; the
        report goes to the run folder's forecast.json."""
        report = fit_forecast(self.model, self.data, self.cfg, np.random.default_rng(self.cfg.train.seed))
        write_text(self.run_dir / "forecast.json", json.dumps(report, indent=1))

    def checkpoint(self, done, elapsed):
        """Write the run's checkpoint after `done` iterations and `elapsed` seconds of training."""
        self.state.elapsed_s = elapsed
        save_checkpoint(self.run_dir, self.cfg, self.model, self.optimizer, self.stats, self.rng, done,
                        dataclasses.asdict(self.state))


def _initial_points(data, n_random, rng):
    """The scene's point cloud, or `n_random` uniform points in its box (grey)."""
    if data.points is not None and len(data.points) >= 2:
        return data.points, data.point_colors
    lo, hi = data.bounds
    return rng.uniform(lo, hi, size=(n_random, 3)), None


def _spread(frames, n):
    if len(frames) <= n:
        return list(frames)
    return [frames[int(i)] for i in np.linspace(0, len(frames) - 1, n).round()]


def _truncate_log(path, iteration):
    """Drop log records after `iteration` (written by a run that then stopped uncheckpointed).

    A torn last line (a crash in the middle of an append) is dropped too; an unreadable line
    before it raises ValueError naming the file and line.
    """
    if not path.is_file():
        return
    lines = path.read_text().splitlines()
    kept = []
    for number, line in enumerate(lines, 1):
        try:
            record = json.loads(line) if line else None
        except json.JSONDecodeError:
            if number == len(lines):
                break
            raise ValueError(f"{path}: line {number}: not a JSON record") from None
        if record is not None and record["iteration"] <= iteration:
            kept.append(line)
    write_text(path, "".join(line + "\n" for line in kept))


@contextlib.contextmanager
def _deferred_interrupt():
    """Turn SIGINT into a flag checked between iterations (main thread only), so Ctrl-C
    never interrupts an optimiser step or a checkpoint write half-way."""
    flag = {"set": False}
    try:
        previous = signal.signal(signal.SIGINT, lambda *_: flag.update(set=True))
    except ValueError:  # not the main thread: leave SIGINT alone
        previous = None
    try:
        yield lambda: flag["set"]
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
