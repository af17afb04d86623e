"""velogauss.walkthrough: the committed docs/walkthrough.md is exactly what the reference
produces today (wall-clock times aside), it covers every ID of spec/index.toml in order, and
every figure it shows exists at a sane size."""

import difflib
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import imageio.v3 as iio
import pytest
from typer.testing import CliRunner

from velogauss.cli import app
from velogauss_core.lpips_nets import CHECKOUT_DIR, ENV_VAR, cache_dir
from velogauss.walkthrough import write_walkthrough
from velogauss.walkthrough.printing import TIMINGS_END, TIMINGS_START

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
INDEX = tomllib.loads((ROOT / "spec" / "index.toml").read_text(encoding="utf-8"))["equation"]
REGENERATE = "python -m velogauss.walkthrough --out docs"
# The figures are drawn 8-12 inches wide at 110 dpi (900-1300 px) and 2.4-8.6 inches tall:
# anything under 300 x 150 px is a broken or empty figure, not a layout choice.
MIN_WIDTH, MIN_HEIGHT = 300, 150
# The figures the walkthrough exists to show (the list); renaming one is fine,
# dropping one is not.
REQUIRED_FIGURES = {"cov-ellipsoids", "proj-dilation", "blend-ray", "basis-fields", "coef-patterns", "integ-circle",
                    "integ-cost", "adf-correction", "transport-residual", "divergence"}
IMAGE_LINK = re.compile(r"!\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^## (VG-[A-Z0-9-]+): (.*)$", re.MULTILINE)


def lpips_weights_present():
    """Whether velogauss_core.lpips_nets finds alex.npz without a download: in $VELOGAUSS_LPIPS_DIR
    when it is set (no fall-through past it), else beside the checkout or in the user cache."""
    env = os.environ.get(ENV_VAR)
    return any((Path(folder) / "alex.npz").is_file() for folder in ([env] if env else [CHECKOUT_DIR, cache_dir()]))


needs_lpips_weights = pytest.mark.skipif(
    not lpips_weights_present(),
    reason="the walkthrough's LPIPS example needs alex.npz (spec/losses_metrics.md lists where it is looked for)")


def without_timings(text):
    """`text` with each block between a TIMINGS_START and a TIMINGS_END line (whole lines)
    replaced by one placeholder line, so that the blocks' number and places still count."""
    kept, inside = [], False
    for number, line in enumerate(text.split("\n"), start=1):
        if line == TIMINGS_START:
            assert not inside, f"line {number}: timings block opened inside another"
            inside = True
            kept.append("<timings>")
        elif line == TIMINGS_END:
            assert inside, f"line {number}: timings block closed without being opened"
            inside = False
        elif not inside:
            kept.append(line)
    assert not inside, "timings block never closed"
    return "\n".join(kept)


def timing_blocks(text):
    """The lines inside each timings block of `text`, one list per block."""
    blocks, current = [], None
    for line in text.split("\n"):
        if line == TIMINGS_START:
            current = []
        elif line == TIMINGS_END:
            blocks.append(current)
            current = None
        elif current is not None:
            current.append(line)
    return blocks


def regenerate(out):
    """Write a fresh walkthrough into `out` by `python -m velogauss.walkthrough` in a new
    interpreter, which must not have imported torch (the reference is NumPy only)."""
    code = ("import runpy, sys; out = sys.argv[1]; sys.argv = ['walkthrough', '--out', out]\n"
            "try:\n    runpy.run_module('velogauss.walkthrough', run_name='__main__')\n"
            "except SystemExit as end:\n    assert not end.code, end.code\n"
            "assert 'torch' not in sys.modules, 'the walkthrough imported torch'")
    result = subprocess.run([sys.executable, "-c", code, str(out)], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def assert_figures_sane(folder):
    """Every image the page in `folder` links to exists, at least MIN_WIDTH x MIN_HEIGHT px, and
    the REQUIRED_FIGURES are among them."""
    links = IMAGE_LINK.findall((folder / "walkthrough.md").read_text(encoding="utf-8"))
    assert {Path(link).stem for link in links} >= REQUIRED_FIGURES
    for link in links:
        path = folder / link
        assert path.is_file(), f"{link} is referenced but missing in {folder}"
        height, width = iio.imread(path).shape[:2]
        assert width >= MIN_WIDTH and height >= MIN_HEIGHT, f"{path} is {width} x {height} px"


# One test for everything that needs a regeneration (~15 s of CPU): under pytest-xdist each
# worker would otherwise regenerate for itself.
@needs_lpips_weights
def test_regenerated_walkthrough_equals_committed_docs(tmp_path):
    regenerate(tmp_path)
    fresh_text = (tmp_path / "walkthrough.md").read_text(encoding="utf-8")
    # What the comparison skips must be wall times only: one table per block, no prose.
    blocks = timing_blocks(fresh_text)
    assert blocks, "no timings block: the VG-INTEG section should time Euler, RK2 and RK4"
    for block in blocks:
        rows = [line for line in block if line]
        assert rows and all(line.startswith("|") for line in rows), block
        assert "wall time" in rows[0], rows[0]
    committed = without_timings((DOCS / "walkthrough.md").read_text(encoding="utf-8"))
    fresh = without_timings(fresh_text)
    if fresh != committed:
        diff = difflib.unified_diff(committed.split("\n"), fresh.split("\n"), "docs/walkthrough.md", "regenerated",
                                    lineterm="", n=1)
        shown = "\n".join(list(diff)[:60])
        pytest.fail(f"docs/walkthrough.md is stale; run `{REGENERATE}` and commit docs/.\n{shown}")
    assert_figures_sane(tmp_path)


def test_committed_figures_exist_with_a_sane_size():
    assert_figures_sane(DOCS)


def test_every_spec_id_has_a_section_in_index_order():
    text = (DOCS / "walkthrough.md").read_text(encoding="utf-8")
    headings = HEADING.findall(text)
    assert [spec_id for spec_id, _ in headings] == [e["id"] for e in INDEX]
    assert [title for _, title in headings] == [e["title"] for e in INDEX]
    sections = re.split(r"^(?=## VG-)", text, flags=re.MULTILINE)[1:]
    for entry, section in zip(INDEX, sections):
        assert f"[`{entry['ref']}`]" in section, f"{entry['id']}: no link to {entry['ref']}"
        assert "```text" in section, f"{entry['id']}: no example run through the reference"


def test_committed_figures_are_all_referenced():
    links = {Path(link).name for link in IMAGE_LINK.findall((DOCS / "walkthrough.md").read_text(encoding="utf-8"))}
    stale = sorted(p.name for p in (DOCS / "figures").iterdir() if p.name not in links)
    assert not stale, f"docs/figures holds files the walkthrough no longer shows, delete them: {stale}"


def test_out_that_is_a_file_raises_naming_out(tmp_path):
    target = tmp_path / "walkthrough.md"
    target.write_text("not a folder")
    with pytest.raises(ValueError, match="^out: "):
        write_walkthrough(target)


def test_cli_bad_out_is_one_error_line_and_exit_code_2(tmp_path):
    target = tmp_path / "a-file"
    target.write_text("")
    result = CliRunner().invoke(app, ["walkthrough", "--out", str(target)])
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: out: ") and str(target) in result.output, result.output
    assert "Traceback" not in result.output
