"""Rewrite the `tests = [...]` lists of spec/index.toml from the @pytest.mark.spec markers,
and the spec table of spec/README.md from spec/index.toml.

Usage: python -m tests.sync_spec_index   (run from the repository root)
"""

import json
import os
import pathlib
import re
import sys
import tomllib

import pytest

from tests.spec_markers import marked_tests

ROOT = pathlib.Path(__file__).resolve().parent.parent
INDEX = ROOT / "spec" / "index.toml"
SPEC_README = ROOT / "spec" / "README.md"
TABLE_START, TABLE_END = "<!-- spec-table:start -->", "<!-- spec-table:end -->"


class _Collector:
    def __init__(self):
        self.items = []

    def pytest_collection_finish(self, session):
        self.items = list(session.items)


def collect_marked():
    """Collect the whole test tree once (no run) and return spec ID -> node ids."""
    collector = _Collector()
    code = pytest.main(
        ["--collect-only", "-q", "-p", "no:xdist", "-p", "no:cacheprovider", str(ROOT / "tests")],
        plugins=[collector],
    )
    if code not in (0, 5):
        sys.exit(f"collection failed with exit code {code}")
    return marked_tests(collector.items)


def main():
    table = collect_marked()
    text = INDEX.read_text()

    def replace(block):
        spec_id = re.search(r'^id = "([^"]+)"', block.group(0), re.M).group(1)
        tests = table.get(spec_id, [])
        listed = "[\n" + "".join(f'  "{t}",\n' for t in tests) + "]" if tests else "[]"
        return re.sub(r"^tests = \[.*?\]", "tests = " + listed, block.group(0), flags=re.M | re.S)

    text = re.sub(r"\[\[equation\]\].*?(?=\n\[\[equation\]\]|\Z)", replace, text, flags=re.S)
    INDEX.write_text(text)
    unknown = sorted(set(table) - set(re.findall(r'^id = "([^"]+)"', text, re.M)))
    if unknown:
        sys.exit(f"markers name IDs missing from the index: {unknown}")
    SPEC_README.write_text(with_spec_table(SPEC_README.read_text(), tomllib.loads(text)["equation"]))


def spec_table(entries):
    """spec/README.md's Markdown table: ID, title, reference function, fast twin, test count.
    Each ID links to its section's file, relative to spec/ (where the table lives)."""
    rows = ["| ID | equation | reference | fast twin | tests |", "|---|---|---|---|---|"]
    for e in entries:
        link = pathlib.Path(os.path.relpath(ROOT / e["section"], SPEC_README.parent)).as_posix()
        rows.append(
            f"| [{e['id']}]({link}) | {e['title']} | `{e['ref']}` | `{e['fast']}` | {len(e['tests'])} |"
        )
    return "\n".join(rows)


def with_spec_table(page, entries):
    """`page` (spec/README.md's text) with the text between the spec-table markers replaced
    by spec_table(entries). The markers must be there: a page without them is an error, not
    a page with a table appended."""
    if TABLE_START not in page or TABLE_END not in page:
        raise ValueError(f"{SPEC_README}: the markers {TABLE_START} and {TABLE_END} are missing")
    head, _, rest = page.partition(TABLE_START)
    _, _, tail = rest.partition(TABLE_END)
    return f"{head}{TABLE_START}\n{spec_table(entries)}\n{TABLE_END}{tail}"


if __name__ == "__main__":
    if sys.argv[1:] == ["--print"]:
        print(json.dumps(collect_marked()))
    else:
        main()
