"""`velogauss bench dnerf`: the D-NeRF reconstruction table of a `velogauss sweep` folder, beside published figures.

The sweep is benchmarks/grids/dnerf_standard.toml (D-NeRF's standard protocol, `data.split = "all"`:
every train frame trains, the test frames score as interpolation; 400 px, black background,
defaults; full model and deformation-only). Per scene and as the mean over the scenes both
ablations finished: PSNR, SSIM and LPIPS (VGG, the network DefGS reports) on D-NeRF's test
frames (the "all" split's interpolation also holds the val frames, left out here), the
Gaussian count at the end of training, the training's wall minutes and its peak resident
memory (the log's `peak_rss_mib`; "—" for runs logged before it was recorded).

The published figures are per-scene test-set numbers at 800x800 with a black background, copied
from the papers' tables: DefGS (Yang et al., "Deformable 3D Gaussians for High-Fidelity Monocular
Dynamic Scene Reconstruction", CVPR 2024, Table 1: 40k iterations on an RTX 3090, LPIPS VGG, lego
scored on its val set) and 4DGS (Wu et al., "4D Gaussian Splatting for Real-Time Dynamic Scene
Rendering", CVPR 2024, appendix Table 7, 800x800 by its Table 1, 20k iterations; its LPIPS
network is not stated).
"""

import json
from pathlib import Path

import numpy as np

from velogauss.bench.harness import markdown_cell
from velogauss.io_utils import write_text

SCENES = ("bouncingballs", "hellwarrior", "hook", "jumpingjacks", "lego", "mutant", "standup", "trex")
# (PSNR, SSIM, LPIPS) per scene, from the tables the module docstring names.
PUBLISHED = {
    "DefGS": {"bouncingballs": (41.01, 0.9953, 0.0093), "hellwarrior": (41.54, 0.9873, 0.0234),
              "hook": (37.42, 0.9867, 0.0144), "jumpingjacks": (37.72, 0.9897, 0.0126),
              "lego": (33.07, 0.9794, 0.0183), "mutant": (42.63, 0.9951, 0.0052),
              "standup": (44.62, 0.9951, 0.0063), "trex": (38.10, 0.9933, 0.0098)},
    "4DGS": {"bouncingballs": (40.62, 0.9942, 0.0155), "hellwarrior": (28.71, 0.9733, 0.0369),
             "hook": (32.73, 0.9760, 0.0272), "jumpingjacks": (35.42, 0.9857, 0.0128),
             "lego": (25.03, 0.9376, 0.0382), "mutant": (37.59, 0.9880, 0.0167),
             "standup": (38.11, 0.9898, 0.0074), "trex": (34.23, 0.9850, 0.0131)},
}
ABLATIONS = ("full", "deform-only")
# D-NeRF's test frames live in this folder of the scene (transforms_test.json's file paths).
TEST_FOLDER = "test"
# Columns of one ablation: (key, header, decimals).
COLUMNS = (("psnr", "PSNR", "{:.2f}"), ("ssim", "SSIM", "{:.4f}"), ("lpips", "LPIPS", "{:.4f}"),
           ("gaussians", "Gaussians", "{:,.0f}"), ("minutes", "train min", "{:.1f}"), ("peak_gb", "peak GB", "{:.2f}"))
# The published figures' cells: PSNR, SSIM, LPIPS.
PUBLISHED_FORMATS = ("{:.2f}", "{:.4f}", "{:.4f}")


def run_row(run_dir):
    """{psnr, ssim, lpips, gaussians, minutes, peak_gb} of a finished run folder (None where not
    recorded), or None when the run has no metrics.json. The image metrics are the means over the
    interpolation frames of D-NeRF's test split (`transforms_test.json`'s, in the folder `test/`),
    what the published tables score; the "all" split also scores the val frames."""
    run_dir = Path(run_dir)
    if not (run_dir / "metrics.json").is_file():
        return None
    frames = json.loads((run_dir / "metrics.json").read_text())["splits"]["interpolation"]["frames"]
    test = [f for f in frames if Path(f["path"]).parent.name == TEST_FOLDER]
    lines = [line for line in (run_dir / "log.jsonl").read_text().splitlines() if line.strip()]
    last = json.loads(lines[-1]) if lines else {}
    peak = last.get("peak_rss_mib")
    return {"psnr": mean([f.get("psnr") for f in test]), "ssim": mean([f.get("ssim") for f in test]),
            "lpips": mean([f.get("lpips_vgg") for f in test]),
            "gaussians": last.get("n_gaussians"),
            "minutes": None if "elapsed_s" not in last else last["elapsed_s"] / 60.0,
            "peak_gb": None if peak is None else peak / 1024}


def collect(sweep_dir, row=run_row):
    """{(scene, ablation): row(run folder), None when unfinished} for the grid's runs `<scene>-<ablation>-s0`."""
    return {(scene, ablation): row(Path(sweep_dir) / f"{scene}-{ablation}-s0")
            for scene in SCENES for ablation in ABLATIONS}


def markdown(rows):
    """The table of `collect`'s rows with the published figures, and its mean row."""
    ours = [f"{a}: {h}" for a in ABLATIONS for _, h, _ in COLUMNS]
    theirs = [f"{name}: {h}" for name in PUBLISHED for h in ("PSNR", "SSIM", "LPIPS")]
    head = ["scene", *ours, *theirs]
    lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    complete = [s for s in SCENES if all(rows[s, a] is not None for a in ABLATIONS)]
    for scene in SCENES:
        cells = [markdown_cell(None if rows[scene, a] is None else rows[scene, a][k], d) for a in ABLATIONS
                 for k, _, d in COLUMNS]
        cells += [markdown_cell(v, d) for name in PUBLISHED for v, d in zip(PUBLISHED[name][scene], PUBLISHED_FORMATS)]
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    means = [markdown_cell(mean([rows[s, a][k] for s in complete]), d) for a in ABLATIONS for k, _, d in COLUMNS]
    means += [markdown_cell(mean([PUBLISHED[name][s][i] for s in complete]), d) for name in PUBLISHED
              for i, d in enumerate(PUBLISHED_FORMATS)]
    lines.append(f"| **mean** ({len(complete)} scenes) | " + " | ".join(means) + " |")
    return "\n".join(lines) + "\n"


def table(sweep_dir, write=None):
    """`velogauss bench dnerf`: the Markdown for the sweep folder `sweep_dir` (also into `write`,
    atomically). FileNotFoundError naming the folder when it holds no finished run of the grid."""
    return write_table(collect(sweep_dir), markdown, "benchmarks/grids/dnerf_standard.toml", sweep_dir, write)


def write_table(rows, render, grid, sweep_dir, write=None):
    """`render(rows)`, also into `write` (atomically); FileNotFoundError naming `sweep_dir` when no
    run of the `grid` file finished (every row None)."""
    if all(row is None for row in rows.values()):
        raise FileNotFoundError(2, f"no finished run of {grid} (run `velogauss sweep` on it first)", str(sweep_dir))
    text = render(rows)
    if write is not None:
        write_text(write, text)
    return text


def mean(values):
    """The mean of the values that are not None; None when none is."""
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None

