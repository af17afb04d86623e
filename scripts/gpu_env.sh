# Sourced by the GPU scripts (gpu_check.sh, gpu_bench.sh) after they set `out`, `budget` and
# `start`: the time left (`left`), the environment every process needs, and OUT/env.txt.
left() { echo $(( budget - ($(date +%s) - start) )); }
mkdir -p "$out"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
# gsplat's kernels for this machine's GPU alone. The same value must reach every process:
# torch writes the architectures into gsplat's build file, and a process that sees another
# value (an unset one too) rebuilds every kernel on its first render (40 s, seen on an H200).
export TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-$(python3 -c 'import torch; print("%d.%d" % torch.cuda.get_device_capability())' 2>/dev/null)}

{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv
  python3 -c 'import sys, torch; print("python", sys.version.split()[0], "torch", torch.__version__, "cuda", torch.version.cuda, torch.cuda.get_device_name(0))'
  nproc; } >"$out/env.txt" 2>&1
