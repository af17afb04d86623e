#!/usr/bin/env bash
# Train every synthetic scene with the full model, and the default scene (toss) under every
# ablation, two runs at a time with one thread each (a 2-core machine), into runs/sweep/.
# Then `python scripts/scene_table.py runs/sweep` prints the results table of the README.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-runs/sweep}
mkdir -p "$out"
jobs=()
for scene in toss spin multi stretch shear grow; do jobs+=("$scene full"); done
for ablation in no-pds no-adf no-gpc deform-only; do jobs+=("toss $ablation"); done
printf '%s\n' "${jobs[@]}" | OMP_NUM_THREADS=1 xargs -P 2 -L 1 bash -c \
  '.venv/bin/velogauss train --scene "$0" --ablation "$1" --out "'"$out"'/$0-$1" > "'"$out"'/$0-$1.log" 2>&1'
