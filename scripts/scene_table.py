"""Print the README's results table from the run folders that scripts/scenes.sh wrote.

Usage: python scripts/scene_table.py RUNS_DIR   (each RUN_DIR/<scene>-<ablation>/ holds
metrics.json from `velogauss train` and log.jsonl with the training time).
"""

import json
import sys
from pathlib import Path


def row(run):
    metrics = json.loads((run / "metrics.json").read_text())
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    interp = metrics["splits"]["interpolation"]["mean"]
    extrap = metrics["splits"]["extrapolation"]["mean"]
    frozen = metrics["freeze_baseline"]["mean"]
    motion = metrics["motion"] or {}
    vel = motion.get("velocity", {}).get("all", {}).get("relative_l2")
    field = motion.get("velocity", {}).get("all", {}).get("field_relative_l2")
    traj = motion.get("trajectory", {}).get("future", {}).get("mean_distance")
    cells = [run.name, f"{interp['psnr']:.2f}", f"{interp['ssim']:.3f}", f"{interp['lpips_alex']:.3f}",
             f"{extrap['psnr']:.2f}", f"{extrap['ssim']:.3f}", f"{extrap['lpips_alex']:.3f}", f"{frozen['psnr']:.2f}",
             "—" if vel is None else f"{vel:.3f}", "—" if field is None else f"{field:.3f}",
             "—" if traj is None else f"{traj:.3f}",
             str(log[-1]["n_gaussians"]), f"{log[-1]['elapsed_s'] / 60:.1f}"]
    return "| " + " | ".join(cells) + " |"


def main(root):
    print("| run | interp PSNR | interp SSIM | interp LPIPS | extrap PSNR | extrap SSIM | extrap LPIPS "
          "| frozen PSNR | particle velocity rel. error | Eulerian field rel. error | future trajectory error "
          "| Gaussians | train min |")
    print("|---|" + "---:|" * 12)
    for run in sorted(p for p in Path(root).iterdir() if (p / "metrics.json").is_file()):
        print(row(run))


if __name__ == "__main__":
    main(sys.argv[1])
