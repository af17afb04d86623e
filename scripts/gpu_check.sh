#!/usr/bin/env bash
# The checks that need a CUDA device, in one run that fits a short lease of a GPU machine.
# Usage: bash scripts/gpu_check.sh OUT_DIR [SECONDS]
# Needs velogauss's dependencies importable by `python3`; GSPLAT_PATH, when set, is a folder
# holding the gsplat package (kept apart so that it joins the path only once compiled).
# SECONDS (default 540) bounds the whole run: each step gets what is left, so a slow step
# cuts the later ones short rather than losing every result. Writes into OUT_DIR:
#   env.txt       the GPU, driver, torch and CUDA versions
#   gsplat.log    gsplat's first-use compilation of its CUDA kernels (in the background,
#                 beside the CUDA tests, since it takes minutes)
#   tests.log     the CUDA cases of the suite (`-k cuda`, the `device`/`backend` fixtures'
#                 cuda parameters), then gsplat against the torch backend
#   train.log     `velogauss train --device cuda` on the default scene, timed
#   metrics.md    its evaluation, when it finished
set -uo pipefail
out=${1:?usage: gpu_check.sh OUT_DIR [SECONDS]}
budget=${2:-540}
start=$(date +%s)
source "$(dirname "$0")/gpu_env.sh"

# gsplat stays off the path of everything else until it has compiled, so that nothing blocks
# on its build lock and the training falls back to the torch backend when the compilation
# fails or runs late. The compilation and the tests stop in time to leave the training its
# last 330 s (the default training took 299 s on an H200).
gsplat_ok=0
if [ -n "${GSPLAT_PATH:-}" ]; then
  ( export PYTHONPATH="$GSPLAT_PATH:$PYTHONPATH" MAX_JOBS=10
    timeout $(( budget - 330 )) python3 -c 'import time; t = time.time()
from gsplat.cuda._backend import _C
print("gsplat compiled:", _C is not None, f"{time.time() - t:.0f} s")' ) >"$out/gsplat.log" 2>&1 &
  compile=$!
fi

timeout $(( budget - 360 )) python3 -m pytest -q -n 4 -p no:cacheprovider -k "cuda and not gsplat" tests \
  >"$out/tests.log" 2>&1
echo "CUDA cases: exit $?, $(( $(date +%s) - start )) s into the run" >>"$out/tests.log"

if [ -n "${GSPLAT_PATH:-}" ]; then
  wait $compile
  if grep -q "gsplat compiled: True" "$out/gsplat.log"; then
    gsplat_ok=1
    export PYTHONPATH="$GSPLAT_PATH:$PYTHONPATH"
    timeout 45 python3 -m pytest -q -p no:cacheprovider tests/fast/test_gsplat_backend.py >>"$out/tests.log" 2>&1
    echo "gsplat cases: exit $?, $(( $(date +%s) - start )) s into the run" >>"$out/tests.log"
  fi
fi

run=$(mktemp -d)/run
echo "gsplat on the path: $gsplat_ok; $(( $(date +%s) - start )) s into the run" >"$out/train.log"
t0=$(date +%s.%N)
timeout "$(left)" python3 -m velogauss train --out "$run" --device cuda >>"$out/train.log" 2>&1
code=$?
echo "train: exit $code, wall $(python3 -c "print(f'{$(date +%s.%N) - $t0:.1f}')") s" >>"$out/train.log"
cp "$run/metrics.md" "$out/" 2>/dev/null
tail -n 3 "$run/log.jsonl" >"$out/log_tail.jsonl" 2>/dev/null
exit 0
