"""What the benchmarks share: the timing loop, peak-memory measurement, the machine line, their
RESULTS.md section."""

import ctypes
import os
import platform
import re
import time
from collections.abc import Callable

import torch

from velogauss.io_utils import write_text
from velogauss.memory import status_kib


def timed_passes(step: Callable[[], object], repeats: int) -> list[float]:
    """Wall seconds of each of `repeats` calls of `step` (perf_counter). The caller warms up
    first and makes `step` wait for its device (torch.cuda.synchronize), so each time covers
    the whole pass."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        times.append(time.perf_counter() - t0)
    return times


def markdown_cell(value, fmt):
    """A table cell of the benchmarks' Markdown: `fmt.format(value)`, "—" for a value not measured."""
    return "—" if value is None else fmt.format(value)


def reset_peak_memory(device):
    """Start a peak-memory measurement; returns the baseline (resident KiB, CUDA bytes).

    Memory freed since the warm-up stays resident in glibc's heap unless trimmed: timed
    passes would reuse it without raising VmHWM and report a peak near 0.
    """
    malloc_trim = getattr(ctypes.CDLL(None), "malloc_trim", None)  # glibc only
    if malloc_trim is not None:
        malloc_trim(0)
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current resident size
    if device == "cpu":
        return status_kib("VmRSS"), 0
    torch.cuda.reset_peak_memory_stats()
    return status_kib("VmRSS"), torch.cuda.memory_allocated()


def peak_above_mib(device, baseline):
    """Peak memory since `reset_peak_memory` above its baseline, in MiB: resident on CPU,
    allocated by torch on CUDA."""
    if device == "cpu":
        return (status_kib("VmHWM") - baseline[0]) / 1024
    return (torch.cuda.max_memory_allocated() - baseline[1]) / 2**20


def machine(device="cpu"):
    """One line naming the CPU, its cores, torch (and its threads) and Python, and the GPU
    with its driver's CUDA version when `device` is a CUDA device."""
    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = re.search(r"^model name\s*:\s*(.+)$", f.read(), re.M).group(1).strip()
    except (OSError, AttributeError):
        pass
    line = (f"{cpu}, {os.cpu_count()} cores, torch {torch.__version__} "
            f"({torch.get_num_threads()} threads), Python {platform.python_version()}")
    if str(device).startswith("cuda"):
        line += f"; GPU {torch.cuda.get_device_name(device)} (CUDA {torch.version.cuda})"
    return line


def device_section(section, device):
    """The results section of a benchmark run on `device`: `section` itself on the CPU, so
    that a CUDA run adds its own section ("## Rasterizer, CUDA") instead of replacing it."""
    return section if device == "cpu" else f"{section}, {str(device).split(':')[0].upper()}"


def regenerate_command(command, *options, quick=False, device="cpu", threads=0):
    """The command line that regenerates a results section: `command`, the benchmark's own
    `options` (strings), then --quick, --device and --threads where they differ from the
    defaults."""
    parts = [command, *options] + (["--quick"] if quick else []) + ([f"--device {device}"] if device != "cpu" else [])
    return " ".join(parts + ([f"--threads {threads}"] if threads else []))


def write_table_section(out_path, section, paragraphs, regenerate, table_lines, device="cpu"):
    """`write_section` in the layout the step benchmarks share: the section heading, the
    `paragraphs`, the machine (with `device`'s GPU), the `regenerate` command line, then the table's lines."""
    text = "\n\n".join([section, *paragraphs, f"Machine: {machine(device)}.", f"Regenerate: `{regenerate}`",
                         "\n".join(table_lines)])
    write_section(out_path, section, text)


def write_section(out_path, section, text):
    """Replace (or append) the `section` ("## ...") of out_path with `text`, leaving the others alone."""
    old = ""
    if os.path.exists(out_path):
        with open(out_path) as f:
            old = f.read()
    if not old.strip():
        old = "# Benchmarks\n"
    pattern = re.compile(rf"^{re.escape(section)}\n.*?(?=^## |\Z)", re.M | re.S)
    body = text.rstrip("\n") + "\n\n"
    new = pattern.sub(lambda _: body, old, count=1) if pattern.search(old) else old.rstrip("\n") + "\n\n" + body
    write_text(out_path, new.rstrip("\n") + "\n")
