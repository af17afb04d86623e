"""The results of a sweep: `results.csv`, `results.md` and one plot per metric.

`run_metrics(run_dir)` reads what `velogauss train`/`eval` left in a run folder
(`metrics.json`, `log.jsonl`, `provenance.json`) into the flat columns of `METRICS` and the
code that trained it; `write_report` writes

- `results.csv`: one row per point (name, scene, ablation, seed, each `set` key, status,
  error, the code that trained it (`velogauss.provenance.code_label`), then the metrics),
  failures included with their error;
- `results.md`: the merged table of every finished run, then the table of mean ± spread
  over seeds (spread: the sample standard deviation, n − 1 in the denominator; a group
  with one seed shows its value alone), with the number of seeds per group;
- `plots/<metric>.png`: per group, each seed's value as a dot and the mean as a bar.

All files are written atomically (`velogauss.io_utils`).
"""

import csv
import io
import json
from pathlib import Path

import numpy as np

from velogauss.io_utils import save_figure, write_text
from velogauss.provenance import code_label

# (column, header of the Markdown table, decimals). Missing values (no ground-truth motion,
# e.g. a DefGS-style run without velocity) are empty in the CSV and "—" in the tables.
METRICS = (
    ("interp_psnr", "interp PSNR", 2), ("interp_ssim", "interp SSIM", 3), ("interp_lpips", "interp LPIPS", 3),
    ("extrap_psnr", "extrap PSNR", 2), ("extrap_ssim", "extrap SSIM", 3), ("extrap_lpips", "extrap LPIPS", 3),
    ("frozen_psnr", "frozen PSNR", 2), ("velocity_rel_error", "particle velocity rel. error", 3),
    ("field_rel_error", "Eulerian field rel. error", 3), ("future_trajectory_error", "future trajectory error", 3),
    ("gaussians", "Gaussians", 0), ("train_min", "train min", 1), ("train_peak_gb", "train peak GB", 2),
)


def run_metrics(run_dir):
    """`{column: value or None}` for `METRICS` from `run_dir`'s metrics.json and log.jsonl, and
    "code": the code that trained it (None for a run from before provenance.json)."""
    run_dir = Path(run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    log = [json.loads(line) for line in (run_dir / "log.jsonl").read_text().splitlines() if line.strip()]
    splits = metrics["splits"]
    interp = splits.get("interpolation", {}).get("mean", {})
    extrap = splits.get("extrapolation", {}).get("mean", {})
    frozen = (metrics.get("freeze_baseline") or {}).get("mean", {})
    motion = metrics.get("motion") or {}
    velocity = motion.get("velocity", {}).get("all", {})
    last = log[-1] if log else {}
    return {
        "interp_psnr": interp.get("psnr"), "interp_ssim": interp.get("ssim"), "interp_lpips": interp.get("lpips_alex"),
        "extrap_psnr": extrap.get("psnr"), "extrap_ssim": extrap.get("ssim"), "extrap_lpips": extrap.get("lpips_alex"),
        "frozen_psnr": frozen.get("psnr"), "velocity_rel_error": velocity.get("relative_l2"),
        "field_rel_error": velocity.get("field_relative_l2"),
        "future_trajectory_error": motion.get("trajectory", {}).get("future", {}).get("mean_distance"),
        "gaussians": last.get("n_gaussians"),
        "train_min": None if "elapsed_s" not in last else last["elapsed_s"] / 60.0,
        "train_peak_gb": None if last.get("peak_rss_mib") is None else last["peak_rss_mib"] / 1024,
        "code": code_label(run_dir),
    }


def write_report(out_dir, points, outcomes):
    """Write results.csv, results.md and plots/ into `out_dir`; return their paths.

    `points`: the sweep's `Point`s; `outcomes`: `{point name: {"status": "ok" | "skipped" |
    "failed" | "pending", "error": str, "metrics": dict or None}}` (points not in it are pending).
    """
    out_dir = Path(out_dir)
    set_keys = list(dict.fromkeys(k for p in points for k, _ in p.settings))
    rows = []
    for p in points:
        outcome = outcomes.get(p.name, {"status": "pending"})
        settings = dict(p.settings)
        rows.append({"run": p.name, "group": p.group, "scene": p.scene or p.data, "ablation": p.ablation,
                     "seed": p.seed, **{k: settings.get(k, "") for k in set_keys}, "status": outcome["status"],
                     "error": outcome.get("error", ""), **(outcome.get("metrics") or {})})
    written = [out_dir / "results.csv", out_dir / "results.md"]
    write_text(written[0], _csv(rows, ["run", "scene", "ablation", "seed", *set_keys, "status", "error", "code",
                                       *[m for m, _, _ in METRICS]]))
    finished = [r for r in rows if r["status"] in ("ok", "skipped")]
    groups = {}
    for row in finished:
        groups.setdefault(row["group"], []).append(row)
    write_text(written[1], _markdown(rows, finished, groups))
    for column, header, _ in METRICS:
        fig = _plot(groups, column, header)
        if fig is None:
            continue
        import matplotlib.pyplot as plt

        try:
            save_figure(out_dir / "plots" / f"{column}.png", fig)
        finally:
            plt.close(fig)
        written.append(out_dir / "plots" / f"{column}.png")
    return written


def _csv(rows, columns):
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: "" if row.get(k) is None else row.get(k) for k in columns})
    return buffer.getvalue()


def _cell(value, decimals):
    return "—" if value is None else f"{value:.{decimals}f}"


def _markdown(rows, finished, groups):
    headers = [h for _, h, _ in METRICS]
    lines = ["# Sweep results", "",
             f"{len(finished)} of {len(rows)} runs finished; "
             f"{sum(r['status'] == 'failed' for r in rows)} failed, {sum(r['status'] == 'pending' for r in rows)} pending.",
             "", "## Every run", "", "| run | " + " | ".join(headers) + " |", "|---|" + "---:|" * len(headers)]
    for row in finished:
        lines.append(f"| {row['run']} | " + " | ".join(_cell(row.get(c), d) for c, _, d in METRICS) + " |")
    lines += ["", "## Mean ± spread over seeds", "",
              "Spread: sample standard deviation over the seeds (n − 1); one seed shows its value alone.", "",
              "| run | seeds | " + " | ".join(headers) + " |", "|---|---:|" + "---:|" * len(headers)]
    for name, members in groups.items():
        cells = []
        for column, _, decimals in METRICS:
            values = [m[column] for m in members if m.get(column) is not None]
            if not values:
                cells.append("—")
            elif len(values) == 1:
                cells.append(_cell(values[0], decimals))
            else:
                cells.append(f"{np.mean(values):.{decimals}f} ± {np.std(values, ddof=1):.{max(decimals, 1)}f}")
        lines.append(f"| {name} | {len(members)} | " + " | ".join(cells) + " |")
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        lines += ["", "## Failed runs", "", "| run | error |", "|---|---|"]
        lines += [f"| {r['run']} | {str(r['error']).replace('|', '/').splitlines()[0] if r['error'] else ''} |"
                  for r in failed]
    return "\n".join(lines) + "\n"


def _plot(groups, column, header):
    """A bar per group (the mean over seeds) with each seed as a dot; None if no value."""
    named = [(name, [m[column] for m in members if m.get(column) is not None]) for name, members in groups.items()]
    named = [(name, values) for name, values in named if values]
    if not named:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(max(4.0, 0.6 * len(named) + 1.5), 3.6))
    x = np.arange(len(named))
    ax.bar(x, [np.mean(v) for _, v in named], color="0.8", label="mean over seeds")
    for i, (_, values) in enumerate(named):
        ax.scatter(np.full(len(values), i), values, s=12, color="tab:blue", zorder=3)
    ax.scatter([], [], s=12, color="tab:blue", label="one seed")
    ax.set_xticks(x, [name for name, _ in named], rotation=45, ha="right", fontsize=7)
    ax.set_ylabel(header)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig
