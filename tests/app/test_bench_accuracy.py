"""Smoke test of velogauss.bench.accuracy: the integrator benchmark runs end to end on its
--quick configuration, writes its section and plot, and measures the convergence orders of
VG-INTEG (1, 2, 4) through base_state. Timings are never asserted (the machine is shared)."""

import re

import numpy as np
import pytest
import torch

from velogauss.bench import accuracy
from velogauss.scenes.catalog import SCENES
from velogauss_fast.motion.coefficients import coefficients
from velogauss_fast.motion.params import params_to_torch
from velogauss_core.motion import MotionSpec

# Ratio of the errors at h and h / 2, per method: 2^p (1 + O(h)). The step sizes of QUICK
# keep |omega| h <= 0.2, where the next term of the error expansion moves the ratio by a
# few percent (seen: Euler 2.05-2.11, RK2 4.00, RK4 16.0 on both motions); +-15 % of 2^p
# covers that and keeps the three bands disjoint, so a method of the wrong order fails.
BAND = 0.15


def section(text, title):
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"no '## {title}' section in:\n{text}"
    return match.group(1)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "RESULTS.md"
    out.write_text("# Benchmarks\n\n## Integrator accuracy vs time\n\nstale\n\n## Other\n\nkeep me\n")
    # One thread: the quick sizes gain nothing from more, and on a shared 2-core machine a
    # second thread contending with other processes made this run 5x slower (32 s vs 6 s).
    results = accuracy.run(str(out), quick=True, threads=1, echo=lambda _: None)
    return out, results


def test_writes_section_table_and_plot(quick_run):
    out, _ = quick_run
    text = out.read_text()
    assert text.count("## Integrator accuracy vs time") == 1 and "stale" not in text
    assert section(text, "Other").strip() == "keep me"
    body = section(text, "Integrator accuracy vs time")
    assert "Regenerate: `velogauss bench accuracy --quick --threads 1`" in body
    rows = [line for line in body.splitlines() if line.startswith("| ") and not line.startswith("| method")]
    assert len(rows) == len(accuracy.ORDERS) * len(accuracy.QUICK.steps)
    assert sum("(default)" in row for row in rows) == 1 and rows[0].startswith("| euler | 0.05 | 20 |")
    png = out.parent / accuracy.PLOT_NAME
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


@pytest.mark.parametrize("key, orders", [
    ("spin_position", accuracy.ORDERS), ("toss_position", accuracy.ORDERS),
    ("spin_angle", accuracy.ANGLE_ORDERS), ("toss_angle", accuracy.ANGLE_ORDERS),
])
def test_errors_halve_at_the_expected_orders(quick_run, key, orders):
    _, results = quick_run
    steps = accuracy.QUICK.steps
    for method, p in orders.items():
        for h, h_half in zip(steps, steps[1:]):
            ratio = results[(method, h)][key] / results[(method, h_half)][key]
            assert abs(ratio / 2**p - 1) <= BAND, (method, h, ratio)


def test_parameters_reproduce_the_scene_coefficients():
    # The motion parameters give every particle the body's exact coefficients at every t
    # (the scene code computes those, independently of the motion model): checked through
    # the fast VG-COEF, float64, against RigidMotion.basis_coefficients.
    cfg = MotionSpec(mask=(True,) * 6 + (False,) * 6)
    for case in accuracy.cases():
        w0, w1 = accuracy.affine_in_time(case.motion)
        params = params_to_torch(accuracy.linear_in_time_params(cfg, w0, w1, np.random.default_rng(0)),
                                 torch.float64, "cpu")
        z = torch.tensor(np.random.default_rng(1).standard_normal((5, cfg.code_dim)))
        for t in (0.0, 0.3, 1.0, 1.7):
            w = coefficients(params, t, z, cfg).numpy()
            expected = case.motion.basis_coefficients(t)
            # Rounding of silu(t) - silu(-t) and of sum(softmax) = 1: a few float64 ulps.
            np.testing.assert_allclose(w, np.broadcast_to(expected, w.shape), rtol=0, atol=1e-13)


def test_catalog_toss_is_not_affine_in_time():
    # Why the benchmark turns the toss's spin vertical: with the catalog's tilted spin the
    # translation coefficients have a -1/2 (omega x g) t^2 term.
    with pytest.raises(ValueError, match="not affine"):
        accuracy.affine_in_time(SCENES["toss"]().bodies[0].motion)
