"""`velogauss bench dnerf-future`: the D-NeRF extrapolation table of a `velogauss sweep` folder
(issue 37, item 3), beside the published anchors.

The sweep is benchmarks/grids/dnerf_future.toml: ODE-GS's protocol (`data.split = "future:0.8"`,
spec/data.md: train and test frames merged and sorted by time, the first 80 % trained, the rest
the future), 400 px, black background, defaults; full model and deformation-only. Per scene and
as the mean over the scenes both ablations finished: the full model's interpolation,
extrapolation and frozen frame (its own reconstruction at the window's end held, the honest
floor) and the margin over it; the deformation-only model's three at the same budget; the full
model's margin over the deformation-only extrapolation; the form that trained the window and the
forecast past it (motion_form.json, forecast.json); the full run's Gaussians and minutes
(probes and training). All PSNR in dB, means over each split's frames (metrics.json).

The anchors are mean extrapolation PSNRs over the 8 scenes at 800 px, second-hand, from notes on
the ODE-GS paper (ICLR 2026): ODE-GS itself, and GaussianPrediction as ODE-GS re-ran it. Neither
reports the frozen frame.
"""

import json
from pathlib import Path

from velogauss.bench.dnerf import ABLATIONS, SCENES, collect, mean, write_table
from velogauss.bench.family import form_label
from velogauss.bench.harness import markdown_cell

# Mean extrapolation PSNR (dB) over the 8 scenes at 800 px, second-hand (module docstring).
ANCHORS = {"ODE-GS (800 px, second-hand)": 27.30, "GaussianPrediction, re-run by ODE-GS (800 px, second-hand)": 23.09}
# The PSNR columns of one ablation: (key, header).
PSNRS = (("interp", "interp"), ("extrap", "extrap"), ("frozen", "frozen"))


def run_row(run_dir):
    """{interp, extrap, frozen, form, gaussians, minutes} of a finished run folder, or None when it
    has no metrics.json; form None where the run chose none (deform-only)."""
    run_dir = Path(run_dir)
    if not (run_dir / "metrics.json").is_file():
        return None
    metrics = json.loads((run_dir / "metrics.json").read_text())
    reports = [json.loads(p.read_text()) if p.is_file() else {}
               for p in (run_dir / "motion_form.json", run_dir / "forecast.json")]
    lines = [line for line in (run_dir / "log.jsonl").read_text().splitlines() if line.strip()] \
        if (run_dir / "log.jsonl").is_file() else []
    last = json.loads(lines[-1]) if lines else {}
    probes = reports[0].get("probe_s", 0.0) + (reports[0].get("window_psnr") or {}).get("probe_s", 0.0)
    return {"interp": _psnr(metrics, "splits", "interpolation"), "extrap": _psnr(metrics, "splits", "extrapolation"),
            "frozen": _psnr(metrics, "freeze_baseline"), "form": form_label(*reports),
            "gaussians": last.get("n_gaussians"),
            "minutes": None if "elapsed_s" not in last else (last["elapsed_s"] + probes) / 60.0}


def markdown(rows):
    """The table of `collect`'s rows, its mean row, the count below the frozen frame and the anchors."""
    head = ["scene", "window, forecast", *(f"full: {h}" for _, h in PSNRS), "full: extrap − frozen",
            *(f"deform-only: {h}" for _, h in PSNRS), "extrap − deform-only", "Gaussians", "min"]
    lines = ["| " + " | ".join(head) + " |", "|---|---|" + "---:|" * (len(head) - 2)]
    complete = [s for s in SCENES if all(rows[s, a] is not None for a in ABLATIONS)]
    for scene in SCENES:
        full, deform = rows[scene, "full"], rows[scene, "deform-only"]
        lines.append(f"| {scene} | {(full or {}).get('form') or '—'} | " + " | ".join(_cells(full, deform)) + " |")
    means = {a: {k: mean([rows[s, a][k] for s in complete]) for k, _ in PSNRS} for a in ABLATIONS}
    lines.append(f"| **mean** ({len(complete)} scenes) | | "
                 + " | ".join(_cells(means["full"], means["deform-only"], counts=False)) + " | | |")
    for name, extrap in ANCHORS.items():
        lines.append(f"| {name} | | | {extrap:.2f} |" + " |" * (len(head) - 4))
    below = [s for s in complete if rows[s, "full"]["extrap"] < rows[s, "full"]["frozen"]]
    lines += ["", f"Full model below its frozen frame: {len(below)} of {len(complete)} scenes"
              + (f" ({', '.join(below)})." if below else ".")]
    return "\n".join(lines) + "\n"


def table(sweep_dir, write=None):
    """`velogauss bench dnerf-future`: the Markdown for the sweep folder `sweep_dir` (also into
    `write`, atomically). FileNotFoundError naming the folder when it holds no finished run of
    the grid."""
    return write_table(collect(sweep_dir, run_row), markdown, "benchmarks/grids/dnerf_future.toml", sweep_dir, write)


def _cells(full, deform, counts=True):
    """A row's cells after the form: full's PSNRs and margin, deform-only's, the margin between them,
    then (with `counts`) full's Gaussians and minutes; "—" where a run or value is missing."""
    full, deform = full or {}, deform or {}
    cells = [markdown_cell(full.get(k), "{:.2f}") for k, _ in PSNRS]
    cells.append(markdown_cell(_difference(full.get("extrap"), full.get("frozen")), "{:+.2f}"))
    cells += [markdown_cell(deform.get(k), "{:.2f}") for k, _ in PSNRS]
    cells.append(markdown_cell(_difference(full.get("extrap"), deform.get("extrap")), "{:+.2f}"))
    if counts:
        cells += [markdown_cell(full.get("gaussians"), "{:,.0f}"), markdown_cell(full.get("minutes"), "{:.1f}")]
    return cells


def _psnr(metrics, *keys):
    for key in keys:
        metrics = metrics.get(key, {})
    return metrics.get("mean", {}).get("psnr")


def _difference(a, b):
    return None if a is None or b is None else a - b
