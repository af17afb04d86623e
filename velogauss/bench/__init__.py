"""Benchmarks: timings and peak memory, each written as its section of benchmarks/RESULTS.md.

`velogauss bench NAME` runs one (`commands`): raster, motion, accuracy, effects, export,
viewer, load, step_profile, step_ratio; `fidelity` runs the motion fidelity study of
benchmarks/FIDELITY.md. `harness` is what they share. The smoke tests (tests/app/test_bench*.py)
run them on their --quick sizes and never assert a timing.
"""
