"""CPU threads of a velogauss process: how many, and how the idle ones wait.

A training step runs hundreds of small torch operations and two large ones (the numba
compositing, forward and backward). torch's CPU threads are GNU OpenMP's (libgomp): with more
than one, every small operation opens a parallel region that ends at a barrier, and beside
another CPU-bound process the workers spin between regions, use up their scheduler credit and
are run late when their work arrives. One torch thread opens no region at all (the numbers:
benchmarks/RESULTS.md, "Where contention comes from" and "Contention"). So, by default:

* torch gets **one** thread: its small operations never wait on a barrier;
* the numba compositing kernels get one thread per core this process may use (its CPU
  affinity, capped by OMP_NUM_THREADS when that is set); they are Python threads that wait
  on a lock, and there are only two such parallel sections per step (a training step's renders
  take one fewer while the auxiliary losses' worker runs: velogauss.train.loop);
* OMP_WAIT_POLICY=PASSIVE (unless already set): should anything still run OpenMP with more
  threads (`--threads N`), idle workers sleep instead of spinning on a core another process
  needs. libgomp reads it once, when it loads: `prepare_environment` must run before torch
  is imported (the `velogauss` command's entry point, `velogauss.cli.main`, does it first).

`--threads N` (config `train.threads`, 0 = the default above) gives torch and the
compositing kernels N threads each.

A script that uses `velogauss_fast` as a library gets the same policy from two public calls
(docs/usage.md, "Threads, from your own script"): `prepare_environment()` before torch is
imported, and `apply_threads(n=0)` after.
"""

import os

WAIT_POLICY = "PASSIVE"


def available_cores():
    """CPUs this process may run on: its affinity mask (taskset, cgroup cpusets), not the machine's count."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no sched_getaffinity (macOS, Windows)
        return os.cpu_count() or 1


def prepare_environment(environ=None):
    """Set OMP_WAIT_POLICY=PASSIVE in `environ` (default os.environ) unless the user set it.

    Takes effect only if torch (hence libgomp) has not been imported yet; returns the policy
    in force for a process started now.
    """
    environ = os.environ if environ is None else environ
    return environ.setdefault("OMP_WAIT_POLICY", WAIT_POLICY)


def resolve_threads(requested, cores, environ=None):
    """(torch threads, compositing threads) for `requested` threads (0: the default).

    requested > 0: that many for both. 0: one torch thread and, for the compositing,
    OMP_NUM_THREADS when it is set to a positive integer, else `cores`.
    Raises ValueError naming `threads` for a negative or non-integer request.
    """
    if isinstance(requested, bool) or not isinstance(requested, int) or requested < 0:
        raise ValueError(f"threads: expected an integer >= 0 (0: automatic), got {requested!r}")
    if requested:
        return requested, requested
    environ = os.environ if environ is None else environ
    budget = environ.get("OMP_NUM_THREADS", "").strip()
    return 1, int(budget) if budget.isdigit() and int(budget) > 0 else max(1, cores)


def apply_threads(requested=0):
    """Set torch's and the compositing kernels' thread counts for `requested` (0: the default,
    see `resolve_threads`); returns (torch threads, compositing threads)."""
    import torch

    from velogauss_fast.backends import numba_backend

    torch_threads, composite_threads = resolve_threads(requested, available_cores())
    torch.set_num_threads(torch_threads)
    numba_backend.set_num_threads(composite_threads)
    return torch_threads, composite_threads
