"""The layering of ARCHITECTURE.md: the library never depends on its own oracle at run time."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# Modules of velogauss that exist to compare with or explain the reference (ARCHITECTURE.md).
_REFERENCE_USERS = ("velogauss/walkthrough/", "velogauss/bench/")


@pytest.mark.parametrize("module", ["velogauss.train.loop", "velogauss.cli", "velogauss.evaluate",
                                    "velogauss_fast.raster", "velogauss_fast.metrics"])
def test_importing_the_library_loads_neither_the_reference_nor_autograd(module):
    code = f"import sys, {module}; print(sorted(m for m in sys.modules if m.split('.')[0] in ('autograd', 'velogauss_ref')))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"{module} loads {out.strip()}"


def _imported_modules(path):
    """The modules `path` imports at its top level (what importing it loads; imports inside
    functions, such as the LPIPS downloader's torch, run only when called)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)


@pytest.mark.parametrize("package, forbidden", [
    ("velogauss_core", ("velogauss_ref", "velogauss_fast", "velogauss", "torch", "autograd")),
    ("velogauss_fast", ("velogauss_ref", "velogauss", "autograd")),
    ("velogauss", ("velogauss_ref", "autograd")),
    ("velogauss_ref", ("velogauss_fast", "velogauss", "torch")),
])
def test_packages_import_only_the_layers_below(package, forbidden):
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if package == "velogauss" and rel.startswith(_REFERENCE_USERS):
            continue
        for module in _imported_modules(path):
            if module.split(".")[0] in forbidden:
                bad.append(f"{rel}: {module}")
    assert not bad, bad
