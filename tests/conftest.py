"""Shared test configuration: hypothesis profiles, the device fixture, spec bookkeeping."""

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

# CI: bounded, derandomized (the same examples every run), no deadline (a 2-core machine
# under xdist has noisy timings; speed is measured in benchmarks/, never asserted here).
settings.register_profile(
    "ci",
    max_examples=25,
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
# Local exploration: more and random examples.
settings.register_profile("dev", max_examples=200, deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def _devices():
    import torch

    devices = ["cpu"]
    devices.append(
        pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device"))
    )
    return devices


@pytest.fixture(params=_devices())
def device(request):
    """Run a test on the CPU and, where a GPU is present, on CUDA."""
    return request.param


@pytest.fixture
def rng():
    """A fixed-seed NumPy generator, so non-hypothesis randomness is repeatable."""
    return np.random.default_rng(0)
