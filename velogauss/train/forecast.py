"""The forecast past the window fitted to a trained model's own paths (`model.future = "fit"`;
spec/motion.md, "The future past the window").

At the end of training, the backtest of "Choosing the form" runs again, on the trained model's
Gaussian paths over the whole window instead of a probe's: each candidate form is fitted on the
heads and scored on the tails (`velogauss.train.backtest.backtest`), and `select` picks one.
- a rigid or harmonic form: fitted to the whole window's paths, it becomes the model's forecast
  (`VeloGaussModel.set_forecast`), which carries every moving Gaussian on from its trained state
  at the window's end;
- the time network: the trained one carries on past the window (the spec's future "integrate");
- no form better than freezing the motion: the future holds (the spec's future "hold").

So the window is reconstructed by the form that fits it best, the time network, and the future
by the form that forecasts it best, each chosen from the video alone.
"""

import dataclasses

import numpy as np

from velogauss.train.backtest import backtest, beats_freezing, candidates, fit, probe_paths, select


def fit_forecast(model, data, cfg, rng):
    """Give `model` (trained, spec.future "fit") its future from its paths on `data`'s training
    frames (module docstring); returns the report: every candidate's tail scores, the choice and
    the future it set ("fit", "integrate" or "hold"). cfg: the run's Config; rng: NumPy Generator
    of the paths' subset and the fits."""
    times, paths = probe_paths(model, data, rng)
    scores = backtest(times, paths, cfg, rng)
    choice = select(scores)
    if not beats_freezing(scores, choice):
        future = "hold"
    elif choice == "mlp":
        future = "integrate"
    else:
        future = "fit"
        form, effects = candidates(cfg.model.effects)[choice]
        motion = fit(form, effects, times, paths, cfg, rng).to(model.gaussians.means.device)
    model.spec = dataclasses.replace(model.spec, future=future)
    model.set_forecast(motion.requires_grad_(False) if future == "fit" else None)
    return {"scores": scores, "choice": choice, "future": future, "points": int(paths.shape[1]),
            "times": [float(t) for t in times]}


def needs_forecast(model):
    """Whether a trained `model` still has its future to fit: spec.future "fit" and no forecast held."""
    return model.spec.future == "fit" and model.forecast is None
