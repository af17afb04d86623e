"""spec/index.toml is complete: every ID has an importable reference, an importable fast
twin, and tests that exist and carry its marker; spec/README.md's table is generated from it."""

import importlib
import json
import pathlib
import re
import subprocess
import sys
import tomllib

import pytest


ROOT = pathlib.Path(__file__).resolve().parent.parent
INDEX = tomllib.loads((ROOT / "spec" / "index.toml").read_text())["equation"]

REQUIRED = [
    "VG-QUAT", "VG-COV", "VG-PROJ", "VG-SH", "VG-ALPHA", "VG-BLEND", "VG-BASIS", "VG-CODE",
    "VG-COEF", "VG-VEL", "VG-INTEG", "VG-ROTSCALE", "VG-ADF", "VG-ACC", "VG-TRANSPORT",
    "VG-DIV", "VG-LOSS", "VG-METRIC",
]


def _resolve(dotted):
    module, _, name = dotted.rpartition(".")
    return getattr(importlib.import_module(module), name)


def test_required_ids_present():
    ids = [e["id"] for e in INDEX]
    assert len(ids) == len(set(ids)), "duplicate IDs in spec/index.toml"
    missing = [i for i in REQUIRED if i not in ids]
    assert not missing, f"required spec IDs missing from spec/index.toml: {missing}"


@pytest.mark.parametrize("entry", INDEX, ids=[e["id"] for e in INDEX])
def test_entry_imports_and_is_documented(entry):
    assert callable(_resolve(entry["ref"])), entry["ref"]
    assert entry["fast"], f"{entry['id']}: no fast twin"
    assert callable(_resolve(entry["fast"])), entry["fast"]
    # Same function name in both packages: the fast path mirrors the reference.
    assert entry["ref"].split(".", 1)[1] == entry["fast"].split(".", 1)[1]
    section = (ROOT / entry["section"]).read_text()
    assert f"## {entry['id']} " in section, f"{entry['id']} has no section in {entry['section']}"


def test_index_tests_match_markers():
    # A separate collection of the whole tree, so the check holds however pytest was invoked.
    out = subprocess.run(
        [sys.executable, "-m", "tests.sync_spec_index", "--print"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    ).stdout
    marked = json.loads(out.strip().splitlines()[-1])
    for entry in INDEX:
        listed = sorted(entry["tests"])
        assert listed, f"{entry['id']}: no test pins it"
        assert listed == marked.get(entry["id"], []), (
            f"{entry['id']}: index lists {listed} but markers say {marked.get(entry['id'], [])}; "
            "run `python -m tests.sync_spec_index`"
        )


def test_spec_readme_table_is_current():
    from tests.sync_spec_index import SPEC_README, with_spec_table

    page = SPEC_README.read_text()
    assert page == with_spec_table(page, INDEX), (
        "spec/README.md's spec table is stale; run `python -m tests.sync_spec_index`"
    )


def test_spec_table_links_resolve():
    """Every ID of spec/README.md's table links to a file that exists, relative to spec/."""
    from tests.sync_spec_index import SPEC_README

    links = re.findall(r"^\| \[VG-[^\]]+\]\(([^)]+)\)", SPEC_README.read_text(), re.M)
    assert len(links) == len(INDEX)
    missing = [link for link in links if not (SPEC_README.parent / link).is_file()]
    assert not missing, f"spec/README.md links to missing files: {missing}"


def test_every_constant_is_named_in_the_spec():
    """spec/conventions.md's constants table lists every constant of velogauss_core.constants."""
    from velogauss_core import constants

    table = (ROOT / "spec" / "conventions.md").read_text().split("## Constants", 1)[1]
    rows = {line.split("|")[1].strip(): line for line in table.splitlines() if line.startswith("| `")}
    names = [n for n in vars(constants) if n.isupper() and not n.startswith("_")]
    assert names, "no constants found"
    missing = [n for n in names if not any(f"`{n}`" in key for key in rows)]
    assert not missing, f"constants missing from spec/conventions.md: {missing}"
