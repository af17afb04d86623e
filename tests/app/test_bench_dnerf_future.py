"""`velogauss bench dnerf-future` (velogauss/bench/dnerf_future.py): the D-NeRF extrapolation table of a
sweep folder, on hand-written run folders whose every number the test chose."""

import json

from typer.testing import CliRunner

from velogauss.bench.dnerf import SCENES
from velogauss.bench.dnerf_future import table
from velogauss.cli import app


def _run(folder, interp, extrap, frozen, gaussians=None, seconds=None, form=None, forecast=None):
    """A run folder whose splits' means are the given PSNRs; `form` and `forecast` its
    motion_form.json and forecast.json (absent when None)."""
    folder.mkdir(parents=True)
    metrics = {"splits": {"interpolation": {"mean": {"psnr": interp}}, "extrapolation": {"mean": {"psnr": extrap}}},
               "freeze_baseline": {"mean": {"psnr": frozen}}}
    (folder / "metrics.json").write_text(json.dumps(metrics))
    last = {"iteration": 9000, "n_gaussians": gaussians, "elapsed_s": seconds}
    (folder / "log.jsonl").write_text(json.dumps({k: v for k, v in last.items() if v is not None}) + "\n")
    for name, report in (("motion_form.json", form), ("forecast.json", forecast)):
        if report is not None:
            (folder / name).write_text(json.dumps(report))


def _rows(text):
    return {line.split(" | ")[0].strip("| *"): line for line in text.splitlines() if line.startswith("|")}


def test_the_table_reads_each_run_margins_and_means_over_scenes_both_ablations_finished(tmp_path):
    # hook: the window went to the time network, a harmonic forecast fitted after it; 600 s of
    # training after 120 + 60 s of probes.
    _run(tmp_path / "hook-full-s0", 30.0, 24.0, 25.0, 7000, 600.0,
         form={"choice": "rigid", "patterns": "mlp", "future": "fit", "probe_s": 120.0,
               "window_psnr": {"mlp": 31.0, "rigid": 28.0, "probe_s": 60.0}},
         forecast={"choice": "harmonic", "future": "fit"})
    _run(tmp_path / "hook-deform-only-s0", 32.0, 21.0, 23.0)
    # lego: the time network's future, held: no probe of the form.
    _run(tmp_path / "lego-full-s0", 20.0, 22.5, 22.0, 9000, 1200.0,
         form={"choice": "mlp", "patterns": "mlp", "future": "hold", "probe_s": 300.0, "window_psnr": None})
    _run(tmp_path / "lego-deform-only-s0", 24.0, 23.0, 21.0)
    _run(tmp_path / "trex-full-s0", 99.0, 99.0, 1.0)  # no deform-only run: not in the mean nor the count
    text = table(tmp_path, write=tmp_path / "t.md")
    assert (tmp_path / "t.md").read_text() == text
    rows = _rows(text)
    assert {*SCENES, "mean** (2 scenes)"} <= set(rows)
    assert rows["hook"] == ("| hook | mlp, forecast harmonic | 30.00 | 24.00 | 25.00 | -1.00 | 32.00 | 21.00 | 23.00 "
                            "| +3.00 | 7,000 | 13.0 |")
    assert rows["lego"] == ("| lego | mlp (held) | 20.00 | 22.50 | 22.00 | +0.50 | 24.00 | 23.00 | 21.00 | -0.50 "
                            "| 9,000 | 25.0 |")
    assert rows["trex"].startswith("| trex | — | 99.00 | 99.00 | 1.00 | +98.00 | — | — | — | — |")
    assert rows["bouncingballs"] == "| bouncingballs | — |" + " — |" * 10
    # Means over hook and lego: interp 25, extrap 23.25, frozen 23.5; deform-only 28, 22, 22.
    assert rows["mean** (2 scenes)"] == ("| **mean** (2 scenes) | | 25.00 | 23.25 | 23.50 | -0.25 | 28.00 | 22.00 | "
                                         "22.00 | +1.25 | | |")
    assert rows["ODE-GS (800 px, second-hand)"].startswith("| ODE-GS (800 px, second-hand) | | | 27.30 |")
    assert text.rstrip().endswith("Full model below its frozen frame: 1 of 2 scenes (hook).")
    # Every row has the header's number of cells.
    widths = {line.count("|") for line in text.splitlines() if line.startswith("|")}
    assert widths == {13}


def test_an_empty_folder_is_an_error_naming_it(tmp_path):
    result = CliRunner().invoke(app, ["bench", "dnerf-future", str(tmp_path)])
    assert result.exit_code == 2 and "no finished run" in result.output and str(tmp_path) in result.output
