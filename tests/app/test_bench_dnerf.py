"""`velogauss bench dnerf` (velogauss/bench/dnerf.py): the D-NeRF table of a sweep folder, on hand-written
run folders whose every number the test chose."""

import json

import pytest
from typer.testing import CliRunner

from velogauss.bench.dnerf import PUBLISHED, SCENES, table
from velogauss.cli import app


def _run(folder, psnr, ssim, lpips, gaussians, seconds, peak_mib=None):
    """A run whose two test frames score psnr ± 1 (mean psnr), and whose val frame scores 0: the
    table reads the test frames alone."""
    folder.mkdir(parents=True)
    frames = [{"path": f"/d/test/r_00{k}.png", "psnr": psnr + d, "ssim": ssim, "lpips_alex": 0.5, "lpips_vgg": lpips}
              for k, d in ((0, -1.0), (1, 1.0))]
    frames.append({"path": "/d/val/r_000.png", "psnr": 0.0, "ssim": 0.0, "lpips_alex": 9.0, "lpips_vgg": 9.0})
    split = {"count": 3, "mean": {"psnr": 0.0}, "frames": frames}
    (folder / "metrics.json").write_text(json.dumps({"splits": {"interpolation": split}}))
    last = {"iteration": 3000, "n_gaussians": gaussians, "elapsed_s": seconds}
    if peak_mib is not None:
        last["peak_rss_mib"] = peak_mib
    (folder / "log.jsonl").write_text(json.dumps({"iteration": 500}) + "\n" + json.dumps(last) + "\n")


def test_the_table_reads_each_run_and_averages_the_scenes_both_ablations_finished(tmp_path):
    _run(tmp_path / "hook-full-s0", 30.0, 0.95, 0.05, 7000, 600.0, 2048.0)
    _run(tmp_path / "hook-deform-only-s0", 32.0, 0.96, 0.04, 9000, 300.0)
    _run(tmp_path / "lego-full-s0", 20.0, 0.85, 0.15, 10000, 1200.0, 3072.0)
    _run(tmp_path / "lego-deform-only-s0", 24.0, 0.90, 0.10, 11000, 900.0)
    _run(tmp_path / "trex-full-s0", 99.0, 0.99, 0.01, 1, 60.0)  # no deform-only run: not in the mean
    text = table(tmp_path, write=tmp_path / "t.md")
    assert (tmp_path / "t.md").read_text() == text
    rows = {line.split(" | ")[0].strip("| *"): line for line in text.splitlines()[2:]}
    assert set(rows) == {*SCENES, "mean** (2 scenes)"}
    # hook: 30 dB, 0.9500, 0.0500 (VGG, not the alex 0.5), 7,000 Gaussians, 10 min, 2 GB; then deform-only, no peak.
    assert rows["hook"].startswith("| hook | 30.00 | 0.9500 | 0.0500 | 7,000 | 10.0 | 2.00 | 32.00 | 0.9600 | 0.0400 | "
                                   "9,000 | 5.0 | — | 37.42 | 0.9867 | 0.0144 | 32.73 |")
    assert rows["bouncingballs"].startswith("| bouncingballs | — | — | — | — | — | — | — |")
    # Means over hook and lego: (30 + 20) / 2, ..., minutes (10 + 20) / 2 and (5 + 15) / 2, peak (2 + 3) / 2.
    mean = rows["mean** (2 scenes)"]
    assert "| 25.00 | 0.9000 | 0.1000 | 8,500 | 15.0 | 2.50 | 28.00 | 0.9300 | 0.0700 | 10,000 | 10.0 | — |" in mean
    assert f"| {(37.42 + 33.07) / 2:.2f} | " in mean and f"| {(32.73 + 25.03) / 2:.2f} | " in mean


def test_the_published_figures_are_the_papers_means():
    # DefGS Table 1 and 4DGS's Table 1 report these means over the 8 scenes (4DGS: 34.05).
    assert sum(PUBLISHED["DefGS"][s][0] for s in SCENES) / 8 == pytest.approx(39.51, abs=0.005)
    assert sum(PUBLISHED["4DGS"][s][0] for s in SCENES) / 8 == pytest.approx(34.05, abs=0.01)


def test_an_empty_folder_is_an_error_naming_it(tmp_path):
    result = CliRunner().invoke(app, ["bench", "dnerf", str(tmp_path)])
    assert result.exit_code == 2 and "no finished run" in result.output and str(tmp_path) in result.output
