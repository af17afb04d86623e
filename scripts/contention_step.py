"""Time the default training iteration and count libgomp's parallel regions in it.

usage: LD_PRELOAD=/tmp/gomp_count.so python scripts/contention_step.py SCENE_DIR THREADS SECONDS
(scripts/contention_diagnosis.sh runs it idle and beside a busy loop; THREADS as
`--threads`, 0 = velogauss's default). Prints one line: wait policy, torch threads, ms per
iteration, parallel regions and the time inside them per iteration.
"""

import ctypes
import os
import sys
import time

import torch

from velogauss.bench.load import training_pass


def main(scene, threads, seconds):
    one_pass, _ = training_pass(scene, threads)
    for _ in range(2):
        one_pass()
    preloaded = ctypes.CDLL(None) if os.environ.get("LD_PRELOAD") else None

    def counters():
        if preloaded is None:
            return 0, 0.0
        return ctypes.c_ulong.in_dll(preloaded, "regions").value, ctypes.c_double.in_dll(preloaded, "seconds").value

    (r0, s0), t0, count = counters(), time.perf_counter(), 0
    while count < 3 or time.perf_counter() - t0 < seconds:
        one_pass()
        count += 1
    elapsed, (r1, s1) = time.perf_counter() - t0, counters()
    print(f"wait={os.environ.get('OMP_WAIT_POLICY', 'default')} torch_threads={torch.get_num_threads()} "
          f"it={1e3 * elapsed / count:.1f}ms n={count} regions/it={(r1 - r0) / count:.0f} "
          f"in_regions/it={1e3 * (s1 - s0) / count:.1f}ms per_region={1e6 * (s1 - s0) / max(1, r1 - r0):.0f}us",
          flush=True)


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]))
