"""Benchmarks: timings and peak memory, written to benchmarks/RESULTS.md (never run by tests)."""
