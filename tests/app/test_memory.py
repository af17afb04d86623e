"""The process's memory accounting (velogauss/memory.py), against numbers the test makes itself."""

import numpy as np

from velogauss.memory import peak_rss_mib, status_kib


def test_peak_grows_by_what_the_process_touches():
    before = peak_rss_mib()
    block = np.ones(64 * 2**20 // 8)  # 64 MiB, every page written
    assert status_kib("VmRSS") / 1024 >= 64
    # The peak can only have grown, and now covers the resident block.
    assert peak_rss_mib() >= max(before, status_kib("VmRSS") / 1024) - 1e-9
    del block


def test_without_proc_the_peak_is_unknown(monkeypatch):
    import builtins

    real_open = builtins.open

    def no_proc(path, *args, **kwargs):
        if str(path).startswith("/proc/"):
            raise FileNotFoundError(path)
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", no_proc)
    assert peak_rss_mib() is None
