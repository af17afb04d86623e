"""The starting frequency of oscillating motion patterns (VG-COEF-HARM), read off the training video.

The frequency the harmonic patterns share is learned, but a gradient moves it only towards
the nearest good fit: the loss of a sinusoid fitted to an oscillation is not convex in their
frequency difference. So training starts it where the video itself oscillates. Each camera
that saw the window at several times gives one pixel time series per pixel (grey level, its
mean removed); for each candidate frequency Ω the series are fitted by least squares with a
mean, cos(Ω t) and sin(Ω t), and the frequency whose fits explain the most variance, summed
over the cameras' pixels, wins. With Y (S, P) one camera's series and H(Ω) (S, S) the
projection onto the three columns at the S frame times, the explained variance is
trace(H(Ω) Y Yᵀ): one S × S Gram matrix per camera, whatever the image size.
"""

import numpy as np
import torch

from velogauss_core.constants import FREQ_SCAN_CYCLES, FREQ_SCAN_MIN_FRAMES, FREQ_SCAN_PIXELS, FREQ_SCAN_STEP


def video_frequency(frames, max_time):
    """(Ω in radians per unit time, or None) of the frames (`velogauss.data` Frames: camera,
    image (H, W, 3), time) inside [0, max_time], scanned over FREQ_SCAN_CYCLES cycles over the
    window. None when no camera saw FREQ_SCAN_MIN_FRAMES distinct times in it (a monocular
    capture, which has one view per time)."""
    omegas = candidate_frequencies(max_time)
    power = np.zeros(len(omegas))
    seen = False
    for times, series in _series_by_camera(frames, max_time):
        seen = True
        gram = series @ series.T  # [S, S]
        for i, omega in enumerate(omegas):
            power[i] += np.trace(_projection(times, omega) @ gram)
    return float(omegas[np.argmax(power)]) if seen else None


def series_frequency(times, series, max_time):
    """(Ω, or None) of time series (S, P) at `times` (S,): the scanned frequency
    (`candidate_frequencies`) whose fits (1, cos, sin) explain the most of their variance, each
    series' mean removed; None with fewer than FREQ_SCAN_MIN_FRAMES times. The backtest
    (velogauss.train.backtest) scans the Gaussians' paths with it."""
    times = np.asarray(times, dtype=np.float64)
    if len(times) < FREQ_SCAN_MIN_FRAMES:
        return None
    series = np.asarray(series, dtype=np.float64)
    series = series - series.mean(0)
    gram = series @ series.T
    omegas = candidate_frequencies(max_time)
    power = [np.trace(_projection(times, omega) @ gram) for omega in omegas]
    return float(omegas[int(np.argmax(power))])


def candidate_frequencies(max_time):
    """The scanned frequencies (radians per unit time): FREQ_SCAN_CYCLES cycles over
    [0, max_time] in steps of FREQ_SCAN_STEP cycles."""
    lo, hi = FREQ_SCAN_CYCLES
    cycles = np.arange(lo, hi + FREQ_SCAN_STEP / 2, FREQ_SCAN_STEP)
    return 2.0 * np.pi * cycles / max_time


def _series_by_camera(frames, max_time):
    """(times (S,), grey-level series (S, P) with each pixel's mean removed) per camera that
    saw at least FREQ_SCAN_MIN_FRAMES distinct times in the window; P is at most
    FREQ_SCAN_PIXELS, an even stride through the image."""
    cameras = {}
    for frame in frames:
        if frame.time <= max_time:
            key = np.asarray(frame.camera.viewmat, dtype=np.float64).round(9).tobytes()
            cameras.setdefault(key, {})[frame.time] = frame.image
    for by_time in cameras.values():
        if len(by_time) >= FREQ_SCAN_MIN_FRAMES:
            times = np.array(sorted(by_time))
            first = np.asarray(by_time[times[0]])
            stride = -(-first.shape[0] * first.shape[1] // FREQ_SCAN_PIXELS)  # ceiling division
            series = np.stack([np.asarray(by_time[t], dtype=np.float64).mean(-1).ravel()[::stride] for t in times])
            yield times, series - series.mean(0)


def _projection(times, omega):
    """H (S, S): the least-squares projection onto (1, cos(Ω t), sin(Ω t)) at the times."""
    X = np.stack([np.ones_like(times), np.cos(omega * times), np.sin(omega * times)], axis=1)
    return X @ np.linalg.pinv(X)


def start_frequency(model, frames, max_time, fallback=None):
    """Set the shared frequency of a fresh model's harmonic patterns (VG-COEF-HARM) to the
    video's (`video_frequency`), else to `fallback` (the backtest probe's paths' frequency,
    velogauss.train.backtest); a model with other patterns, or without either estimate
    (the frequency then stays at HARMONIC_CYCLES_INIT cycles), is left as it is. Returns the
    frequency set, or None."""
    spec = model.spec
    if not (spec.moving and spec.velocity == "affine" and spec.pattern_form == "harmonic"):
        return None
    omega = video_frequency(frames, max_time)
    omega = fallback if omega is None else omega
    if omega is not None:
        with torch.no_grad():
            model.motion.time[1].fill_(omega)
    return omega
