"""Smoke tests of velogauss/bench: each benchmark runs end to end through `velogauss bench NAME`
on its --quick workload and writes a well-formed section of a results file. Timings are never
asserted (the machine is shared); only the tables' structure and the benchmarks' own
correctness checks are."""

import os
import re

import pytest
import torch
from typer.testing import CliRunner

from velogauss.bench import motion, raster
from velogauss.bench.harness import device_section, write_section
from velogauss.cli import app

# The 'before' tree of the step ratio's smoke tests: the last commit whose training draws the same
# random numbers from the same images as this tree (move it when a change alters either on
# purpose: 43f50f2 keeps images as 8 bits).
BEFORE = "43f50f2"


def bench(*args):
    """`velogauss bench ARGS...` in this process; asserts it succeeded."""
    result = CliRunner().invoke(app, ["bench", *map(str, args)])
    assert result.exit_code == 0, result.output
    return result


@pytest.fixture
def one_thread():
    """The benchmarks' arguments for one torch thread (on a busy 2-core machine, two spin
    against each other and a pass takes 20x longer); gives the test process its threads back."""
    threads = torch.get_num_threads()
    yield ["--threads", "1"]
    torch.set_num_threads(threads)


def section(text, title):
    """The body of the `## title` section of a results file."""
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, f"no '## {title}' section in:\n{text}"
    return match.group(1)


def table(body):
    """(header cells, rows of cells) of the one markdown table in a section body."""
    lines = [line for line in body.splitlines() if line.startswith("|")]
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines]
    assert set(cells[1]) <= {"---", "---:"}, lines[1]
    assert all(len(row) == len(cells[0]) for row in cells), lines
    return cells[0], cells[2:]


def test_raster_bench_quick(tmp_path, one_thread):
    out = tmp_path / "RESULTS.md"
    out.write_text("# Benchmarks\n\n## Rasterizer\n\nstale\n\n## Other\n\nkeep me\n")
    bench("raster", "--quick", "--in-process", "--out", out, *one_thread)
    text = out.read_text()
    assert text.count("## Rasterizer") == 1 and "stale" not in text
    assert section(text, "Other").strip() == "keep me"
    body = section(text, "Rasterizer")
    assert "Regenerate: `velogauss bench raster --workloads quick --rounds 1 --threads 1`" in body
    header, rows = table(body)
    assert header == ["workload", "method", "median fwd+bwd (s)", "time / default", "peak RSS (MiB)",
                      "peak above start (MiB)", "memory / default", "image sum", "note"]
    assert [row[1] for row in rows] == list(raster.METHODS)
    # gsplat needs CUDA: its row says why it was skipped; every other method ran.
    skipped = [row for row in rows if row[2] == "-"]
    assert [row[1] for row in skipped] == ["gsplat"] and skipped[0][-1] == "needs CUDA and the gsplat package"
    rows = [row for row in rows if row[2] != "-"]
    for row in rows:
        assert row[0] == "quick 12x12, 24 G" and row[-1] == "1 runs in 1 rounds, 1 threads", row
        # Times print with 3 decimals: a sub-millisecond pass reads 0.000.
        assert float(row[2]) >= 0 and float(row[4]) > 0 and row[3].endswith("x") and row[6].endswith("x")
    # Every method renders the same image: float32 (numba, torch, autograd, dense) against the
    # float64 reference, 144 pixels of O(1) values: sums agree to ~1e-5 relative.
    sums = [float(row[7]) for row in rows]
    assert max(sums) - min(sums) <= 1e-4 * max(sums), sums


def test_motion_bench_quick(tmp_path, one_thread):
    out = tmp_path / "RESULTS.md"
    bench("motion", "--quick", "--in-process", "--out", out, *one_thread)
    body = section(out.read_text(), "Motion and residuals")
    assert "Regenerate: `velogauss bench motion --quick --threads 1`" in body
    header, rows = table(body)
    assert header == ["case", "median (s)", "time / forward-mode", "peak memory above start (MiB)",
                      "memory / forward-mode", "note"]
    assert len(rows) == len(motion.CASES)
    assert rows[0][0] == "base_state RK2, 256 particles x 2 steps: forward"
    for row in rows:
        assert float(row[1]) >= 0 and row[-1] == "1 runs, 1 threads", row
    # The forward-mode and jacrev residuals agree, on residuals that are not all zero.
    match = re.search(r"max abs difference over r and div: (\S+) in float32 \(max \|r\| = (\S+), "
                      r"max \|div\| = (\S+)\), (\S+) in float64", body)
    diff32, r_max, div_max, diff64 = (float(g.rstrip(",")) for g in match.groups())
    assert r_max > 1e-3 and div_max > 1e-3
    # Rounding of two summation orders: observed ~1e-15 (float64), ~1e-6 (float32) relative.
    scale = max(r_max, div_max)
    assert diff64 <= 1e-12 * scale and diff32 <= 1e-5 * scale


@pytest.mark.parametrize("measure, key", [
    (lambda: raster.measure("dense", "quick", 1, "cpu", threads=1), "peak_above_start_mib"),
    (lambda: motion.measure("trajectory-fwdbwd", 1, "cpu", 1, quick=True), "peak_mib"),
])
def test_a_measurement_in_a_fresh_process_returns_its_result(measure, key):
    # The benchmark module run as a script is the fresh process: its result comes back as JSON.
    result = measure()
    assert "skipped" not in result, result
    assert len(result["times"]) == 1 and result["median_s"] > 0 and key in result and result["threads"] == 1


def test_effects_bench_quick(tmp_path):
    from velogauss.bench import effects

    threads = torch.get_num_threads()
    try:
        rows = effects.run(tmp_path / "RESULTS.md", quick=True)
    finally:
        torch.set_num_threads(threads)
    header, cells = table(section((tmp_path / "RESULTS.md").read_text(), effects.SECTION[3:]))
    assert len(cells) == len(rows) == 4
    every, declared, frozen, static = rows
    # What each profile builds follows from the scene's declaration (multi: rigid, with a static ground).
    assert (every["columns"], declared["columns"], static["columns"]) == (12, 6, 0)
    assert 0 < frozen["moving"] < declared["moving"] == declared["n"]
    # A static scene builds no motion: its physics cost is exactly nothing.
    assert static["physics_s"] == 0.0 and every["physics_s"] > 0


def test_load_bench_quick(tmp_path):
    from velogauss.bench import load

    out = tmp_path / "RESULTS.md"
    bench("load", "--quick", "--settings", "velogauss", "--workloads", "numba,train", "--out", out)
    body = section(out.read_text(), "Contention")
    assert "Regenerate: `velogauss bench load --settings velogauss --workloads numba,train --quick`" in body
    header, rows = table(body)
    assert header == ["setting", "workload", "idle (ms)", "beside a busy process (ms)", "beside a 2nd training (ms)",
                      "slowdown busy", "slowdown training", "threads (torch / compositing)"]
    assert [row[:2] for row in rows] == [["velogauss", "numba"], ["velogauss", "train"]]
    for row in rows:
        idle, busy, training = (float(v) for v in row[2:5])
        assert idle > 0 and busy > 0 and training > 0
        # The ratios are the table's own times divided (times rounded to 0.01 ms, ratios to 0.01).
        assert float(row[5].rstrip("x")) == pytest.approx(busy / idle, rel=0.02, abs=0.01)
        assert float(row[6].rstrip("x")) == pytest.approx(training / idle, rel=0.02, abs=0.01)
        # The workers start without the caller's OMP_NUM_THREADS: the default setting's
        # torch thread and one compositing thread per available core.
        assert row[7] == f"1 / {len(os.sched_getaffinity(0))}"


def test_load_bench_refuses_unknown_settings(tmp_path):
    from velogauss.bench import load

    with pytest.raises(ValueError, match="settings: unknown setting 'fast'"):
        load.run(str(tmp_path / "R.md"), settings=("fast",))
    with pytest.raises(ValueError, match="--device"):
        load.run(str(tmp_path / "R.md"), device="cuda")


def test_step_profile_at_real_resolution_quick(tmp_path):
    from velogauss.bench import step_profile

    out = tmp_path / "RESULTS.md"
    bench("step_profile", "--quick", "--sizes", "24,32", "--gaussians", "150", "--out", out)
    body = section(out.read_text(), "Training step profile at real resolution")
    assert "Regenerate: `velogauss bench step_profile --sizes 24,32 --gaussians 150 --quick`" in body
    header, rows = table(body)
    assert header == ["part", "24 px, 150 points", "32 px, 150 points"]
    assert [row[0].replace("&nbsp;", "") for row in rows] == (
        ["iteration, unprofiled (ms)", "Gaussians trained"] + [label for label, _, _ in step_profile.PARTS])
    assert rows[1][1:] == ["150", "150"]  # the point cloud's size is the trained count
    assert all(cell.endswith("(100%)") for cell in rows[2][1:])  # the step's row is the whole step
    with pytest.raises(ValueError, match="--sizes, --gaussians: give both"):
        step_profile.run(str(out), sizes=[400])


def test_step_profile_quick(tmp_path):
    from velogauss.bench import step_profile

    out = tmp_path / "RESULTS.md"
    bench("step_profile", "--quick", "--out", out)
    body = section(out.read_text(), "Training step profile")
    assert "Regenerate: `velogauss bench step_profile --quick`" in body
    header, rows = table(body)
    assert header == ["part", "ms per iteration", "% of the step", "calls per iteration"]
    assert [row[0].replace("&nbsp;", "") for row in rows] == [label for label, _, _ in step_profile.PARTS]
    # Every part was found in the profile (a renamed function would read 0 calls) and the
    # step is one call per iteration; its parts are inside it.
    calls = {row[0].replace("&nbsp;", ""): float(row[3]) for row in rows}
    assert all(c > 0 for c in calls.values()), calls
    assert calls["step (`Trainer.step`)"] == 1
    step_ms = float(rows[0][1])
    assert all(float(row[1]) <= step_ms for row in rows[1:] if row[0].startswith("&nbsp;"))


def _needs_before():
    import subprocess

    if subprocess.run(["git", "cat-file", "-e", f"{BEFORE}^{{commit}}"], capture_output=True).returncode:
        pytest.skip(f"the 'before' revision {BEFORE} is not in this clone")


def test_step_ratio_quick(tmp_path):
    from velogauss.bench import step_ratio

    _needs_before()
    out = tmp_path / "RESULTS.md"
    result = step_ratio.run(str(out), revision=BEFORE, quick=True)
    body = section(out.read_text(), "Training step: before / after")
    assert f"Regenerate: `velogauss bench step_ratio --before {BEFORE} --quick`" in body
    header, rows = table(body)
    assert header == ["round", "before (ms per iteration)", "after (ms per iteration)", "before / after"]
    assert len(rows) == step_ratio.QUICK_ROUNDS
    # Both versions train the same iterations from the same start, so they differ by rounding
    # at most: the last loss within 1e-5, which a wrong gradient would break; the parameters
    # within 5 %, since Adam's epsilon of 1e-15 turns the rounding of near-zero gradients into
    # whole steps. (Worker against inline, to the last bit: tests/app/test_train.py.)
    assert result["agreement"] and all(diff < 0.05 * max(scale, 1.0) for diff, scale in result["agreement"].values())
    assert result["losses"][1] == pytest.approx(result["losses"][0], rel=1e-5)


def test_library_quick_times_a_users_script_of_both_trees(tmp_path):
    _needs_before()
    out = tmp_path / "RESULTS.md"
    bench("library", "--quick", "--before", BEFORE, "--out", out)
    body = section(out.read_text(), "Library use")
    assert f"Regenerate: `velogauss bench library --before {BEFORE} --quick`" in body
    header, rows = table(body)
    assert header == ["tree", "backend", "idle (ms)", "beside a busy 2-thread torch process (ms)", "slowdown"]
    assert [row[:2] for row in rows] == [[f"`{BEFORE}`", "numba"], [f"`{BEFORE}`", "torch"], ["this tree", "numba"],
                                         ["this tree", "torch"]]
    for row in rows:
        idle, busy = float(row[2]), float(row[3])
        assert idle > 0 and busy > 0
        # One round: the slowdown is the table's own times divided. The times are rounded to 0.1 ms,
        # and the quick workload's are under a millisecond, so the ratio of the rounded times is
        # bounded by the rounding's interval, not by a relative tolerance.
        slowdown = float(row[4].rstrip("x"))
        assert (busy - 0.05) / (idle + 0.05) - 0.005 <= slowdown <= (busy + 0.05) / max(idle - 0.05, 1e-9) + 0.005


def test_library_refuses_a_gpu(tmp_path):
    result = CliRunner().invoke(app, ["bench", "library", "--device", "cuda", "--out", str(tmp_path / "R.md")])
    assert result.exit_code != 0 and "the library benchmark measures CPU threads" in result.output
    assert not (tmp_path / "R.md").exists()


def test_a_cuda_run_adds_its_own_section_and_keeps_the_cpu_one(tmp_path):
    out = tmp_path / "R.md"
    write_section(out, device_section("## Rasterizer", "cpu"), "## Rasterizer\n\ncpu numbers")
    cuda = device_section("## Rasterizer", "cuda:1")
    assert cuda == "## Rasterizer, CUDA"
    write_section(out, cuda, f"{cuda}\n\ncuda numbers")
    text = out.read_text()
    assert "cpu numbers" in text and "cuda numbers" in text
    assert text.index("## Rasterizer\n") < text.index("## Rasterizer, CUDA\n")
    # A new CPU run replaces its own section only.
    write_section(out, "## Rasterizer", "## Rasterizer\n\nnew cpu numbers")
    text = out.read_text()
    assert "new cpu numbers" in text and "cuda numbers" in text and "\ncpu numbers" not in text


def test_step_ratio_at_a_given_size_has_its_own_section(tmp_path):
    from velogauss.bench import step_ratio

    _needs_before()
    out = tmp_path / "RESULTS.md"
    write_section(out, step_ratio.SECTION, f"{step_ratio.SECTION}\n\nthe default size's numbers")
    bench("step_ratio", "--before", BEFORE, "--quick", "--gaussians", 321, "--out", out)
    text = out.read_text()
    assert "the default size's numbers" in text
    body = section(text, "Training step: before / after, 321 Gaussians")
    # Both versions trained the point cloud's 321 Gaussians (the quick scene's own has 200).
    assert "with a point cloud of 321 points (321 Gaussians;" in body
    assert f"Regenerate: `velogauss bench step_ratio --before {BEFORE} --gaussians 321 --quick`" in body
    assert len(table(body)[1]) == step_ratio.QUICK_ROUNDS


def test_step_ratio_needs_a_revision_and_refuses_a_size_below_one():
    runner = CliRunner()
    result = runner.invoke(app, ["bench", "step_ratio", "--quick"])
    assert result.exit_code == 2 and "--before" in result.output, result.output
    result = runner.invoke(app, ["bench", "step_ratio", "--before", BEFORE, "--gaussians", "0"])
    assert result.exit_code == 2 and "--gaussians" in result.output, result.output


def test_gpu_step_quick_on_the_cpu(tmp_path):
    # Without CUDA the static step is not timed, and the table says so; the dynamic step is.
    out = tmp_path / "RESULTS.md"
    bench("gpu_step", "--quick", "--device", "cpu", "--out", out)
    body = section(out.read_text(), "The dynamic step against gsplat's static step")
    assert "Regenerate: `velogauss bench gpu_step --device cpu --quick`" in body
    header, rows = table(body)
    assert header[:2] == ["size", "Gaussians"] and len(rows) == 1
    size, count, views, dynamic, static, ratio = rows[0]
    assert (size, count, views) == ("24 px", "200", "3") and float(dynamic) > 0
    assert (static, ratio) == ("gsplat not available", "—")


def test_gpu_step_refuses_a_missing_device_and_bad_sizes(tmp_path):
    from velogauss.bench import gpu_step

    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="--device: device 'cuda' is not available"):
            gpu_step.run(str(tmp_path / "R.md"))
    with pytest.raises(ValueError, match="--size: expected a whole number of at least 16, got 8"):
        gpu_step.run(str(tmp_path / "R.md"), device="cpu", size=8)
    assert not (tmp_path / "R.md").exists()
