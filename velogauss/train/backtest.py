"""The motion patterns' form chosen by backtesting (config `model.patterns = "auto"`; spec/motion.md,
"Choosing the form").

A forecaster picks a model by how it predicts what it was not fitted on; so does this, from
the video alone, never from a scene's name or declared effects:

1. `probe`: a short run with the time network's patterns (`BACKTEST_PROBE_SHARE` of the run's
   iterations, its schedule scaled with it) recovers the Gaussians' trajectories over the
   observed window [0, T];
2. `probe_paths`: the moving, opaque Gaussians' positions at the training frame times;
3. `backtest`: each candidate form (`CANDIDATES`: rigid bodies whose centres drift or
   accelerate, oscillators, the time network) is fitted, as the velocity model alone (the
   "no-adf" motion), to the paths' velocities on the head of the window t <= h T, then
   integrated from the head's last positions over the held-out rest, and scored by the RMS
   position error there over the RMS of the motion since the head's end (1 is as bad as
   freezing the motion there), at each forecast origin h of `BACKTEST_HEADS` (forecasting's
   rolling origin);
4. `select`: walking the candidates from the fewest free parameters to the most, a richer form
   replaces the choice only when it predicts better at every origin; the choice stands when its
   mean score is below 1, else the time network;
5. `window_psnr`: a form that forecasts may still reconstruct the window worse; a second probe,
   trained with the chosen form, renders the window's training frames, and when it scores more
   than FORM_WINDOW_DB below the time network's probe the window goes to the time network and
   the form's role to the forecast fitted at the end of training (`model.future = "fit"`,
   velogauss.train.forecast). Otherwise the choice is the run's `model.patterns` (and, for a
   drifting rigid centre, its effects without gravity); the run then trains from scratch with
   it, as if it had been set. Where the window is the time network's (chosen, or left to it by a
   rigid form), whose probe may have learned no motion that reverses and so left paths that show
   none, a probe with the oscillators is trained; when it renders the window more than
   OSCILLATOR_WINDOW_DB above the time network's probe, the oscillators train the window and the
   backtest runs again on their probe's paths, whose scores decide the future. When no
   candidate beat freezing, `model.future = "auto"` becomes "hold": past the window the run
   shows the persistence forecast, which the backtest found best. config.toml records both,
   and the run folder's `motion_form.json` holds every candidate's scores.

The choice is a forecast's, so it is made only where the window leaves a frame to forecast
(`leaves_a_future`). A window that reaches t = 1 (D-NeRF's standard protocol, every frame
trained) takes the time network's patterns without a probe (`nothing_to_forecast`): they fit
the window best, and a form chosen on held-out tails cost up to 5.5 dB inside it
(benchmarks/FIDELITY.md, 0q).

The probe also says whether still Gaussians lie beside moving ones (`model.mixing_init =
"auto"`: the mixing weights then start apart) and, for oscillators, the paths' own frequency,
which starts the harmonic patterns when the video gives none (a monocular capture).
"""

import dataclasses
import tempfile
import time

import numpy as np
import torch

from velogauss.config import PERIODS, SCHEDULE, resolve_schedule
from velogauss.model.motion import MotionParameters
from velogauss.model.spec import resolve_motion_spec
from velogauss.train.frequency import series_frequency
from velogauss.train.mixing import cluster_targets, separate_patterns
from velogauss.train.optim import acceleration_group
from velogauss_core.constants import (BACKTEST_HEADS, BACKTEST_CLUSTERS, BACKTEST_LR, BACKTEST_MAX_TIMES, BACKTEST_POINTS,
                                      BACKTEST_PROBE_SHARE, BACKTEST_STEPS, FORM_WINDOW_DB, OSCILLATOR_WINDOW_DB,
                                      RIGID_HULL_OPACITY, WINDOW_FRAMES)
from velogauss_core.motion import UNDECLARED_EFFECTS
from velogauss_fast.motion.basis import affine_from_coefficients, basis_matrix
from velogauss_fast.motion.code import physics_code
from velogauss_fast.motion.coefficients import (masked, mixing_weights, motion_patterns_at,
                                                 rigid_velocity_patterns)
from velogauss_fast.motion.trajectory import base_state
from velogauss_fast.metrics import psnr

# The candidates, from the fewest free parameters per pattern to the most: name -> (pattern
# form, the effects it may keep of the run's). "rigid-drift" drops gravity (2 knots: 9
# numbers), "rigid" keeps it (3 knots, a centre under a constant acceleration: 12), the
# oscillators have 37, the time network thousands; None keeps every effect.
CANDIDATES = {
    "rigid-drift": ("rigid", ("translation", "rotation", "static")),
    "rigid": ("rigid", ("translation", "rotation", "gravity", "static")),
    "harmonic": ("harmonic", None),
    "mlp": ("mlp", None),
}


def candidates(effects):
    """{name: (form, effects)} of CANDIDATES, in their order, that the run's `effects` (a tuple,
    or "auto": every effect but oscillation) allow: a rigid candidate keeps its share of them and
    needs translation or rotation among it; "rigid-drift" is left out when the effects hold no
    gravity (it would be "rigid" again)."""
    base = UNDECLARED_EFFECTS if effects == "auto" else tuple(effects)
    out = {}
    for name, (form, keep) in CANDIDATES.items():
        kept = base if keep is None else tuple(e for e in base if e in keep)
        if keep is not None and not {"translation", "rotation"} & set(kept):
            continue
        if name == "rigid-drift" and kept == tuple(e for e in base if e in CANDIDATES["rigid"][1]):
            continue
        out[name] = (form, kept)
    return out


def selects_form(cfg):
    """Whether a new run of `cfg` chooses its patterns by backtest: `model.patterns = "auto"`
    under an ablation with the affine velocity (the patterns' only reader)."""
    return cfg.model.patterns == "auto" and cfg.model.ablation in ("full", "no-adf", "no-gpc")


def choose_form(cfg, data, run, progress=False):
    """(cfg with `model.patterns`, `model.effects` and `model.mixing_init` resolved, report dict)
    for a new run of `cfg` on `data` (velogauss.data.SceneData). `run(cfg, data, run_dir,
    progress=...) -> model` trains the probe (velogauss.train.loop.train). The report: every
    candidate's tail score, the choice, the probe's moving share, its paths' frequency, and the
    seconds the probe and the backtest took."""
    if not leaves_a_future(data):
        return nothing_to_forecast(cfg)
    clock = time.perf_counter()
    model = probe(cfg, data, run, progress)
    probe_s = time.perf_counter() - clock
    times, paths = probe_paths(model, data, np.random.default_rng(cfg.train.seed))
    moving_share = float(model.moving.float().mean())
    report = {"probe_iterations": probe_config(cfg).train.iterations, "moving_share": moving_share,
              "points": int(paths.shape[1]), "times": [float(t) for t in times]}
    m = cfg.model
    mixing = m.mixing_init
    if mixing == "auto":
        # Still Gaussians beside moving ones: more than one motion to tell apart from the start.
        mixing = "clusters" if 0.0 < moving_share < 1.0 else "uniform"
    scores = backtest(times, paths, cfg, np.random.default_rng(cfg.train.seed))
    heads = [float(times[last]) for last in origins(times)] if scores else []
    moved = paths.shape[1] > 0
    choice = select(scores)
    form, effects = candidates(m.effects)[choice]
    effects = m.effects if choice == "mlp" or form == "harmonic" else effects
    frequency = series_frequency(times, paths.reshape(len(times), -1), float(times[-1])) if moved else None
    future, window = m.future, None
    asks = future in ("auto", "fit")
    if choice != "mlp" and asks:
        # Does the form reconstruct the window? A second probe, trained with it, against the first.
        clock_form = time.perf_counter()
        shaped = probe(cfg, data, run, progress, frequency, patterns=form, effects=effects, mixing_init=mixing)
        window = {"mlp": window_psnr(model, data), choice: window_psnr(shaped, data),
                  "probe_s": time.perf_counter() - clock_form}
        if window[choice] < window["mlp"] - FORM_WINDOW_DB:
            # It forecasts but does not reconstruct: the time network trains the window, and the
            # forecast is fitted to the trained paths at the end (velogauss.train.forecast).
            form, effects, future = "mlp", m.effects, "fit"
    if asks and form == "mlp" and CANDIDATES[choice][0] != "harmonic" and "harmonic" in candidates(m.effects):
        # A time network that learned no motion which reverses (an oscillation) leaves paths that
        # show none, or a form fitted to them: a probe with the oscillators asks the images instead.
        clock_form = time.perf_counter()
        shaped = probe(cfg, data, run, progress, frequency, patterns="harmonic", effects=m.effects,
                       mixing_init=mixing)
        window = {"probe_s": 0.0, **(window or {"mlp": window_psnr(model, data)}),
                  "harmonic": window_psnr(shaped, data)}
        window["probe_s"] += time.perf_counter() - clock_form
        if window["harmonic"] > window["mlp"] + OSCILLATOR_WINDOW_DB:
            # The oscillators train the window; their probe's paths, not the first's, say whether
            # they forecast better than freezing.
            times, paths = probe_paths(shaped, data, np.random.default_rng(cfg.train.seed))
            report["first_scores"], report["first_choice"] = scores, choice
            scores = backtest(times, paths, cfg, np.random.default_rng(cfg.train.seed))
            if scores:
                frequency = series_frequency(times, paths.reshape(len(times), -1), float(times[-1]))
            choice, form, effects, future = "harmonic", "harmonic", m.effects, m.future
    if future == "auto":
        future = "integrate" if beats_freezing(scores, choice) else "hold"
    model_cfg = dataclasses.replace(m, patterns=form, mixing_init=mixing, effects=effects, future=future)
    report.update({"origins": heads, "scores": scores, "choice": choice, "window_psnr": window, "patterns": form,
                   "future": future, "mixing_init": mixing, "frequency": frequency, "probe_s": probe_s,
                   "backtest_s": time.perf_counter() - clock - probe_s})
    return dataclasses.replace(cfg, model=model_cfg), report


def leaves_a_future(data):
    """Whether the observed window leaves a frame to forecast: it ends more than one frame
    interval (the median gap between the distinct training times) before t = 1, the end of the
    time axis (spec/conventions.md). A window that reaches it has nothing to hold out for."""
    times = np.unique([f.time for f in data.train])
    gap = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    return 1.0 - data.max_time > gap


def nothing_to_forecast(cfg):
    """(cfg, report) of a run whose window reaches the end of the time axis (`leaves_a_future`):
    the time network's patterns, which fit a window best, with the mixing started uniform and the
    motion integrated where "auto", and no probe. The report says why and has no scores."""
    m = cfg.model
    mixing = "uniform" if m.mixing_init == "auto" else m.mixing_init
    future = "integrate" if m.future == "auto" else m.future
    model_cfg = dataclasses.replace(m, patterns="mlp", mixing_init=mixing, future=future)
    report = {"choice": "mlp", "future": future, "mixing_init": mixing, "scores": {}, "frequency": None,
              "reason": "the observed window reaches t = 1: nothing to forecast, no probe"}
    return dataclasses.replace(cfg, model=model_cfg), report


def probe_config(cfg, **model):
    """The probe's config: `cfg` with the time network's patterns (or the `model` keys given), for
    BACKTEST_PROBE_SHARE of its iterations, every key of the schedule (SCHEDULE, "auto" or set)
    scaled with them (intervals to at least 1), so that its window opens as the run's does; no
    evaluations or checkpoints."""
    model = {"patterns": "mlp", **model}
    full = resolve_schedule(dataclasses.replace(cfg, model=dataclasses.replace(cfg.model, **model)))
    iterations = max(1, round(BACKTEST_PROBE_SHARE * cfg.train.iterations))
    changes = {"train": {"iterations": iterations, "eval_every": 0, "checkpoint_every": 0}, "model": model}
    for name in SCHEDULE:
        section, key = name.split(".")
        value = round(getattr(getattr(full, section), key) * iterations / cfg.train.iterations)
        changes.setdefault(section, {})[key] = max(1, value) if name in PERIODS else value
    return dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **values)
                                       for section, values in changes.items()})


def probe(cfg, data, run, progress=False, frequency=None, **model):
    """The probe's trained model (`probe_config` with the `model` keys), trained in a temporary
    folder; `frequency`: the start of harmonic patterns where the video gives none."""
    with tempfile.TemporaryDirectory(prefix="velogauss-probe-") as folder:
        return run(probe_config(cfg, **model), data, folder, progress=progress, frequency=frequency)


def window_psnr(model, data):
    """Mean PSNR (dB) of `model`'s renders of WINDOW_FRAMES of `data`'s training frames, evenly
    spread: how well a probe reconstructs the window. Training frames only: the held-out ones
    score the run, and choosing by them would leak them into it."""
    frames = data.train
    frames = [frames[int(i)] for i in np.unique(np.linspace(0, len(frames) - 1, WINDOW_FRAMES).round())]
    ref = model.gaussians.means
    background = torch.as_tensor(data.background, dtype=ref.dtype, device=ref.device)
    with torch.no_grad():
        return float(np.mean([float(psnr(model.render(f.camera, f.time, background)[0].clamp(0, 1),
                                         torch.as_tensor(f.image, dtype=ref.dtype, device=ref.device)))
                              for f in frames]))


def probe_paths(model, data, rng):
    """(times (J,), paths (J, M, 3) float64): the positions of up to BACKTEST_POINTS moving
    Gaussians, at least RIGID_HULL_OPACITY times as opaque as the most opaque moving one, at
    the distinct training times in [0, max_time] (at most BACKTEST_MAX_TIMES, evenly picked,
    0 and max_time kept)."""
    times = np.unique([f.time for f in data.train if f.time <= data.max_time + 1e-9])
    if len(times) > BACKTEST_MAX_TIMES:
        times = times[np.unique(np.round(np.linspace(0, len(times) - 1, BACKTEST_MAX_TIMES)).astype(int))]
    with torch.no_grad():
        opacity = torch.sigmoid(model.gaussians.opacity_logits)
        moving = model.moving.clone()
        if moving.any():
            moving &= opacity >= RIGID_HULL_OPACITY * opacity[moving].max()
        index = torch.nonzero(moving).flatten().cpu().numpy()
        if len(index) > BACKTEST_POINTS:
            index = np.sort(rng.choice(index, BACKTEST_POINTS, replace=False))
        paths = np.stack([model.state_at(float(t))[0][index].double().cpu().numpy() for t in times])
    return times, paths


def select(scores):
    """The chosen candidate (module docstring, step 4) of `scores` {name: [score per origin]}, in
    CANDIDATES' order: "mlp" when there are none or the choice's mean score is not below 1 (the
    paths show no law that predicts better than freezing the motion)."""
    choice = None
    for name, row in scores.items():
        if choice is None or all(a < b for a, b in zip(row, scores[choice])):
            choice = name
    return choice if choice is not None and np.mean(scores[choice]) < 1.0 else "mlp"


def beats_freezing(scores, choice):
    """Whether the chosen candidate predicts the held-out tails better than freezing the motion:
    its mean score below 1. Without scores (nothing moved, or no tail to hold out) nothing was
    shown to, and the run's future holds (`model.future = "auto"`)."""
    return choice in scores and float(np.mean(scores[choice])) < 1.0


def origins(times):
    """The heads' last indices (sorted, distinct) into `times` (J >= 4,): per h of BACKTEST_HEADS
    the last time <= h times[-1], with at least 3 times to fit (a parabola) and 1 to score."""
    lasts = []
    for share in BACKTEST_HEADS:
        last = int(np.flatnonzero(times <= share * times[-1] + 1e-9)[-1])
        lasts.append(min(max(last, 2), len(times) - 2))
    return sorted(set(lasts))


def backtest(times, paths, cfg, rng):
    """{candidate: [tail score per origin]} (module docstring, step 3) for the paths (J, M, 3) at
    J `times`: at each origin (`origins`) each candidate is fitted on the head, then integrated
    from the head's last positions over the rest. Empty when nothing moved (M = 0) or there is
    no tail to hold out (J < 4)."""
    if paths.shape[1] == 0 or len(times) < 4:
        return {}
    scores = {name: [] for name in candidates(cfg.model.effects)}
    for last in origins(times):
        spread = np.sqrt(((paths[last + 1:] - paths[last]) ** 2).sum(-1).mean())
        for name, (form, effects) in candidates(cfg.model.effects).items():
            motion = fit(form, effects, times[:last + 1], paths[:last + 1], cfg, rng)
            predicted = predict(motion, paths[0], paths[last], times[last:])[1:]
            error = np.sqrt(((predicted - paths[last + 1:]) ** 2).sum(-1).mean())
            scores[name].append(float(error / max(spread, 1e-12)))
    return scores


def candidate_spec(form, effects, cfg, max_time):
    """The velocity-only ("no-adf") MotionSpec of a candidate form (`candidates`) over [0, max_time]."""
    model_cfg = dataclasses.replace(cfg.model, ablation="no-adf", patterns=form, effects=effects, future="integrate")
    return resolve_motion_spec(model_cfg, None, max_time)


def fit(form, effects, times, paths, cfg, rng):
    """A `MotionParameters` of the candidate fitted to the paths (J, M, 3) at `times` (J,).

    The paths are clustered (k-means of start and displacements, BACKTEST_CLUSTERS) and each
    cluster gets a pattern of its own (`separate_patterns` on those labels); a rigid or
    harmonic pattern starts at its cluster's least-squares fit (`rigid_fit`, `harmonic_fit`).
    Then the velocity field (VG-VEL, codes at the paths' first positions) is fitted by Adam
    (BACKTEST_STEPS steps at BACKTEST_LR, decaying 100x; the acceleration group of the time
    network's candidate at the training's ratio of `train.lr_acc` to `train.lr_motion`) to the
    paths' velocities, their finite differences in time."""
    spec = candidate_spec(form, effects, cfg, float(times[-1]))
    motion = MotionParameters(spec, rng)
    x0 = torch.as_tensor(paths[0], dtype=torch.float32)
    velocities = np.gradient(paths, times, axis=0)
    labels = cluster_paths(paths, min(BACKTEST_CLUSTERS, spec.n_patterns), rng)
    separate_patterns(motion, x0, rng, labels=labels)
    if form == "rigid":
        _start_patterns(motion, form, times, paths, velocities, labels, None)
    elif form == "harmonic":
        omega = series_frequency(times, paths.reshape(len(times), -1), float(times[-1]))
        _start_patterns(motion, form, times, paths, velocities, labels, omega)
    fast = acceleration_group(motion)
    slow = [p for p in motion.parameters() if all(p is not f for f in fast)]
    # Started at their least-squares fit, the fast group refines at the networks' rate; the
    # time network starts still and takes the training's ratio of the two.
    ratio = cfg.train.lr_acc / cfg.train.lr_motion if form == "mlp" else 1.0
    optimizer = torch.optim.Adam([{"params": slow, "lr": BACKTEST_LR}, {"params": fast, "lr": BACKTEST_LR * ratio}])
    base_rates = [g["lr"] for g in optimizer.param_groups]
    x = torch.as_tensor(paths, dtype=torch.float32)
    v = torch.as_tensor(velocities, dtype=torch.float32)
    t = torch.as_tensor(times, dtype=torch.float32)
    for step in range(BACKTEST_STEPS):
        decay = 0.01 ** (step / BACKTEST_STEPS)
        for group, rate in zip(optimizer.param_groups, base_rates):
            group["lr"] = rate * decay
        loss = ((_velocities(motion, x0, x, t) - v) ** 2).sum(-1).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return motion


def cluster_paths(paths, k, rng):
    """labels (M,) in [0, k): k-means of the paths (J, M, 3) by start position and displacements,
    so that points that move differently, or not at all, fall apart."""
    features = np.concatenate([paths[0], (paths - paths[0]).transpose(1, 0, 2).reshape(paths.shape[1], -1)], axis=1)
    labels, _ = cluster_targets(features, min(k, len(features)), rng)
    return labels


def _start_patterns(motion, form, times, paths, velocities, labels, omega):
    """Every pattern set to the least-squares fit of all the paths, then each cluster's (row
    `label` of the time parameters) to its own: the weight a point puts on the other patterns
    then pulls it towards the scene's mean motion, not towards stillness."""
    spec = motion.spec
    if form == "harmonic" and omega is None:
        return
    groups = [(list(range(spec.n_patterns)), np.ones(len(labels), dtype=bool))]
    # A cluster of fewer than 4 points does not fix an affine or rigid field.
    groups += [([int(label)], labels == label) for label in np.unique(labels) if (labels == label).sum() >= 4]
    with torch.no_grad():
        for rows, members in groups:
            x, v = paths[:, members], velocities[:, members]
            if form == "rigid":
                motion.time[rows] = torch.as_tensor(rigid_fit(times, x, v, spec), dtype=motion.time.dtype)
            else:
                fitted = torch.as_tensor(harmonic_fit(times, x, v, omega, spec.mask), dtype=motion.time[0].dtype)
                motion.time[0][:, rows] = fitted[:, None]
        if form == "harmonic":
            motion.time[1].fill_(omega)


def rigid_fit(times, x, v, spec):
    """A VG-COEF-RIGID row (ω, knots) whose field best fits the velocities v at x (J, m, 3):
    per time ω_j and u_j of v = ω_j × x + u_j, the spin their mean, then the knots whose
    ċ(t) − ω × c(t) best fits the u_j (linear in the knots, read off the public pattern)."""
    J = len(times)
    spins = np.stack([np.linalg.lstsq(rigid_design(x[j]), v[j].reshape(-1), rcond=None)[0][:3] for j in range(J)])
    omega = spins.mean(0)
    u = (v - np.cross(omega, x)).mean(1)  # [J, 3]
    n = spec.rigid_knots
    t = torch.as_tensor(times, dtype=torch.float64)[:, None, None]
    columns = []
    for unit in np.eye(3 * n):
        row = torch.as_tensor(np.concatenate([omega, unit]), dtype=torch.float64)[None]
        columns.append(rigid_velocity_patterns(row, t, spec.max_time)[:, 0, :3].numpy().reshape(-1))
    knots = np.linalg.lstsq(np.stack(columns, axis=1), u.reshape(-1), rcond=None)[0]
    return np.concatenate([omega, knots])


def rigid_design(x):
    """(3m, 6) design of v = ω × x + u at the points x (m, 3): ω × x = −[x]× ω."""
    m = len(x)
    design = np.zeros((m, 3, 6))
    design[:, 0, 1], design[:, 0, 2] = x[:, 2], -x[:, 1]
    design[:, 1, 0], design[:, 1, 2] = -x[:, 2], x[:, 0]
    design[:, 2, 0], design[:, 2, 1] = x[:, 1], -x[:, 0]
    design[:, :, 3:] = np.eye(3)
    return design.reshape(3 * m, 6)


def harmonic_fit(times, x, v, omega, mask):
    """VG-COEF-HARM blocks (3, 12) (a, b, c) of one pattern: per time the affine coefficients
    w_j of v = Phi(x) w_j (least squares over the masked columns), then each column's series
    fitted by a + b cos(Ω t) + c sin(Ω t)."""
    columns = np.ones(12, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    w = np.zeros((len(times), 12))
    for j in range(len(times)):
        design = basis_matrix(torch.as_tensor(x[j])).numpy()[:, :, columns].reshape(-1, columns.sum())
        w[j, columns] = np.linalg.lstsq(design, v[j].reshape(-1), rcond=None)[0]
    series = np.stack([np.ones_like(times), np.cos(omega * times), np.sin(omega * times)], axis=1)
    return np.linalg.lstsq(series, w, rcond=None)[0]


def _velocities(motion, x0, x, times):
    """Phi(x) m(z) P(t) (J, M, 3) at positions x (J, M, 3) and times (J,), z = E(gamma(x0))."""
    params, spec = motion.params(), motion.spec
    m = mixing_weights(params, physics_code(params, x0, spec))  # [M, K]
    w = masked(m @ motion_patterns_at(params, times, spec), spec.mask)  # [J, M, 12]
    A, b = affine_from_coefficients(w)
    return (A * x[..., None, :]).sum(-1) + b


def predict(motion, x0, x_start, times):
    """Positions (J, M, 3) float64 of the fitted `motion` at `times` (J,), starting from
    x_start (M, 3) at times[0]; the codes are taken at x0 (M, 3), the paths' first positions."""
    params, spec = motion.params(), motion.spec
    with torch.no_grad():
        z = physics_code(params, torch.as_tensor(x0, dtype=torch.float32), spec)
        x = torch.as_tensor(x_start, dtype=torch.float32)
        q = x.new_zeros(len(x), 4)
        q[:, 0] = 1.0
        s = x.new_ones(len(x), 3)
        out, t_prev = [x], float(times[0])
        for t in times[1:]:
            x, q, s = base_state(params, x, q, s, z, float(t), spec.step, spec.integrator, spec, t0=t_prev)
            out.append(x)
            t_prev = float(t)
        return np.stack([p.double().numpy() for p in out])
