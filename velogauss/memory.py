"""The process's resident memory, as Linux accounts it (/proc/self/status), for logs and benchmarks."""

import re


def status_kib(field):
    """A /proc/self/status field in KiB (VmRSS, VmHWM, ...)."""
    with open("/proc/self/status") as f:
        return int(re.search(rf"^{field}:\s+(\d+) kB", f.read(), re.M).group(1))


def peak_rss_mib():
    """The process's peak resident memory so far (VmHWM) in MiB; None where /proc does not give it
    (not Linux)."""
    try:
        return status_kib("VmHWM") / 1024
    except (OSError, AttributeError):
        return None
