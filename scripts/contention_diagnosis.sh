#!/usr/bin/env bash
# Where the slowdown under shared cores comes from (benchmarks/RESULTS.md, "Where contention
# comes from"): the default training iteration with two torch threads under libgomp's default,
# PASSIVE and ACTIVE wait policies, and with velogauss's default (one torch thread), idle and
# beside a busy loop, counting libgomp's parallel regions (scripts/gomp_count.c). Needs gcc.
set -euo pipefail
cd "$(dirname "$0")/.."
unset OMP_NUM_THREADS MKL_NUM_THREADS NUMBA_NUM_THREADS OMP_WAIT_POLICY
secs=${SECS:-5}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
gcc -O2 -shared -fPIC -o "$work/gomp_count.so" scripts/gomp_count.c -ldl
.venv/bin/python -c "import sys; from velogauss.bench.load import make_default_scene; make_default_scene(sys.argv[1])" "$work/scene"
run() {  # label condition threads VAR=value...
  local label=$1 condition=$2 threads=$3 competitor=""
  shift 3
  if [ "$condition" = busy ]; then .venv/bin/python -c "while True: pass" & competitor=$!; sleep 0.5; fi
  echo "$label $condition: $(env "$@" LD_PRELOAD="$work/gomp_count.so" GOMP_COUNT_QUIET=1 \
    .venv/bin/python scripts/contention_step.py "$work/scene" "$threads" "$secs" | tail -1)"
  if [ -n "$competitor" ]; then kill "$competitor"; wait "$competitor" 2>/dev/null || true; fi
}
echo "uptime: $(uptime)"
for condition in idle busy; do
  run "2 threads, libgomp default wait" "$condition" 2 -u OMP_WAIT_POLICY
  run "2 threads, PASSIVE" "$condition" 2 OMP_WAIT_POLICY=PASSIVE
  run "2 threads, ACTIVE" "$condition" 2 OMP_WAIT_POLICY=ACTIVE
  run "velogauss default (1 torch thread)" "$condition" 0 OMP_WAIT_POLICY=PASSIVE
done
echo "uptime: $(uptime)"
