#!/usr/bin/env bash
# Issue 38's GPU figures, in one run that fits 8 minutes of a lent GPU machine.
# Usage: bash scripts/gpu_bench.sh OUT_DIR [SECONDS] [DNERF_SCENE]
# Needs velogauss's dependencies importable by `python3`; GSPLAT_PATH, when set, is a folder
# holding the gsplat package (joins the path only once compiled, as in scripts/gpu_check.sh).
# SECONDS (default 450) bounds the whole run; each step gets what is left. DNERF_SCENE is a D-NeRF
# scene folder carried to the machine (default benchmarks/grids/dnerf/lego, about 25 MB).
# Writes into OUT_DIR:
#   env.txt        the GPU, driver, torch and CUDA versions
#   gsplat.log     gsplat's first-use compilation of its CUDA kernels
#   RESULTS.md     `velogauss bench gpu_step`: the dynamic step at 800 px with 100k Gaussians against
#                  gsplat's static 3DGS step (the floor), then the default scene's step (128 px, 2,000
#                  Gaussians) on the GPU; its CPU figure is `velogauss bench gpu_step --device cpu
#                  --size 128 --gaussians 2000` on the CPU machine
#   dnerf.log      `velogauss train DNERF_SCENE` at 800 px (future:0.8, black) on the GPU until the
#                  time runs out; dnerf_log.jsonl its progress (iterations, elapsed seconds)
set -uo pipefail
out=${1:?usage: gpu_bench.sh OUT_DIR [SECONDS] [DNERF_SCENE]}
budget=${2:-450}
scene=${3:-benchmarks/grids/dnerf/lego}
start=$(date +%s)
source "$(dirname "$0")/gpu_env.sh"

# The default scene's step needs no gsplat (the torch backend): it runs while gsplat compiles.
if [ -n "${GSPLAT_PATH:-}" ]; then
  ( export PYTHONPATH="$GSPLAT_PATH:$PYTHONPATH" MAX_JOBS=10
    timeout 240 python3 -c 'import time; t = time.time()
from gsplat.cuda._backend import _C
print("gsplat compiled:", _C is not None, f"{time.time() - t:.0f} s")' ) >"$out/gsplat.log" 2>&1 &
  compile=$!
fi
timeout 90 python3 -m velogauss bench gpu_step --device cuda --size 128 --gaussians 2000 --out "$out/RESULTS.md" \
  >"$out/default_step.log" 2>&1
echo "default scene's step: exit $?, $(( $(date +%s) - start )) s into the run" >>"$out/default_step.log"
cp "$out/RESULTS.md" "$out/RESULTS_default_step.md" 2>/dev/null  # the next bench replaces the section
if [ -n "${GSPLAT_PATH:-}" ]; then
  wait $compile
  grep -q "gsplat compiled: True" "$out/gsplat.log" && export PYTHONPATH="$GSPLAT_PATH:$PYTHONPATH"
fi
timeout 150 python3 -m velogauss bench gpu_step --device cuda --out "$out/RESULTS.md" >"$out/gpu_step.log" 2>&1
echo "800 px step: exit $?, $(( $(date +%s) - start )) s into the run" >>"$out/gpu_step.log"

run=$(mktemp -d)/run
t0=$(date +%s.%N)
timeout "$(left)" python3 -m velogauss train "$scene" --out "$run" --device cuda --background black \
  --set data.split=future:0.8 --no-eval >"$out/dnerf.log" 2>&1
echo "D-NeRF at 800 px: exit $?, wall $(python3 -c "print(f'{$(date +%s.%N) - $t0:.1f}')") s" >>"$out/dnerf.log"
cp "$run/log.jsonl" "$out/dnerf_log.jsonl" 2>/dev/null
exit 0
