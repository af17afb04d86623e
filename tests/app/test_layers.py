"""The layering of ARCHITECTURE.md: the library never depends on its own oracle at run time."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
# Modules of velogauss that exist to compare with or explain the reference (ARCHITECTURE.md).
_REFERENCE_USERS = ("velogauss/walkthrough/", "velogauss/bench/")


@pytest.mark.parametrize("module", ["velogauss.train.loop", "velogauss.cli", "velogauss.run", "velogauss.evaluate",
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


def _imports_anywhere(path):
    """Every module `path` imports, at its top level or inside functions (`from velogauss import
    cli` counts as `velogauss.cli`)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
            yield from (f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)


def test_only_entry_points_import_the_command_line():
    # velogauss.cli is the console script's module: what the commands share lives below it
    # (velogauss.run, velogauss.errors), and no library module reaches up into it. The
    # `python -m` entry points (`__main__.py`) are the exception: they run the command.
    bad = [f"{path.relative_to(ROOT).as_posix()}: {module}"
           for path in sorted((ROOT / "velogauss").rglob("*.py")) if path.name != "__main__.py"
           for module in _imports_anywhere(path) if module == "velogauss.cli" or module.startswith("velogauss.cli.")]
    assert not bad, bad


# Private names of other packages imported on purpose, with the reason next to the import.
_THIRD_PARTY_PRIVATE = {
    ("viser._scene_api", "_encode_image_binary"),  # velogauss/bench/viewer.py: the viewer's own JPEG encoder
}


def _private_imports(path, package):
    """(line, module, name) of every import in `path` (top level or inside functions) that
    names a private module or object (`_x`, not `__x__`); relative imports resolve to `package`."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                module = f"{package}.{module}" if module else package
            for alias in node.names:
                parts = module.split(".") + [alias.name]
                if any(p.startswith("_") and not p.startswith("__") for p in parts):
                    yield node.lineno, module, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if any(p.startswith("_") and not p.startswith("__") for p in alias.name.split(".")):
                    yield node.lineno, alias.name, ""


@pytest.mark.parametrize("package", ["velogauss_core", "velogauss_ref", "velogauss_fast", "velogauss"])
def test_no_module_imports_a_private_name(package):
    # "The same public names in ref and fast, no cross-module imports of private names": what
    # two modules share is public and documented; a private name stays in its module.
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for line, module, name in _private_imports(path, package):
            if (module, name) not in _THIRD_PARTY_PRIVATE:
                bad.append(f"{rel}:{line}: from {module} import {name}")
    assert not bad, bad


def test_the_private_import_scan_sees_private_imports(tmp_path):
    # The scan itself, on imports of every form it must catch (and one it must not).
    source = tmp_path / "m.py"
    source.write_text("from velogauss_fast.nn import mlp, _hidden\n"
                      "from velogauss_fast._kernels import run\n"
                      "import velogauss._private.mod\n"
                      "from . import _sibling\n"
                      "from .spec import MotionSpec\n"
                      "def f():\n    from velogauss.cli import _helper\n"
                      "from velogauss import __version__\n")
    found = [(module, name) for _, module, name in _private_imports(source, "velogauss.model")]
    assert found == [("velogauss_fast.nn", "_hidden"), ("velogauss_fast._kernels", "run"),
                     ("velogauss._private.mod", ""), ("velogauss.model", "_sibling"), ("velogauss.cli", "_helper")]
