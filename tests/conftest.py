"""Shared test configuration: hypothesis profiles, the device fixture, spec bookkeeping."""

import os

# Under pytest-xdist every worker would otherwise start one BLAS and one torch thread per
# core: with `-n 2` on 2 cores that oversubscribes the machine and makes small NumPy/torch
# calls up to 10x slower. One thread per worker; set before NumPy/torch load their pools.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")

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


def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import torch

        torch.set_num_threads(1)


def pytest_generate_tests(metafunc):
    """Parametrize `device` and `backend` arguments.

    A test taking `device` runs on the CPU and, where a GPU is present, on CUDA (skipped
    cleanly without one). A test taking `backend` as well runs once per rasterizer backend
    of each device: "torch" (vectorised) and "numba" (compiled, CPU only) on the CPU,
    "torch" on CUDA.
    """
    import torch

    cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
    if "backend" in metafunc.fixturenames:
        metafunc.parametrize(("device", "backend"),
                             [("cpu", "torch"), ("cpu", "numba"), pytest.param("cuda", "torch", marks=cuda)],
                             ids=["cpu-torch", "cpu-numba", "cuda-torch"])
    elif "device" in metafunc.fixturenames:
        metafunc.parametrize("device", ["cpu", pytest.param("cuda", marks=cuda)])


@pytest.fixture
def rng():
    """A fixed-seed NumPy generator, so non-hypothesis randomness is repeatable."""
    return np.random.default_rng(0)
