"""The layer rule of DESIGN.md, checked on the source (issue 12 items 1, 2 and 5).

Layers, top to bottom: cli -> api -> reporting -> analysis -> design -> models -> io. A module
may import its own layer and the layers below, never above (anywhere in the file, also
inside functions: a lazy import still makes the lower layer depend on the upper one), with
one exception: a result's ``plot`` method may import ``reporting`` or ``api`` inside its body.
A result's picture is drawn by ``reporting`` (issue 21: ``result.plot()`` delegating to it),
and the import runs only when a person asks for the picture, so the lower layer still loads,
runs and is tested without the upper one; a module-level import, or one in any other
function, is still forbidden.
matplotlib is imported only by reporting code: no other module may load it when it is
imported (checked in a fresh interpreter, import by import).
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src"
PKG = SRC / "airbearing"
#: Layer ranks: a module may import modules of the same or a lower rank.
RANK = {"io": 0, "models": 1, "design": 2, "analysis": 3, "reporting": 4, "api": 5, "cli": 6}


def _module(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "airbearing" or len(parts) < 2:
        return None
    return parts[1] if parts[1] in RANK else None


def _imports(path: Path) -> list[tuple[int, str, bool]]:
    """``(line, imported module, at module level)`` for every absolute import in a file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top = {id(n) for n in tree.body}
    # imports under a module-level `if`/`try` run at import too
    for n in tree.body:
        if isinstance(n, ast.If | ast.Try):
            top |= {id(c) for c in ast.walk(n)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, id(node) in top) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
            if node.module == "airbearing":  # from airbearing import analysis
                names = [f"airbearing.{a.name}" for a in node.names]
            out += [(node.lineno, n, id(node) in top) for n in names]
    return out


#: The layers a ``plot`` method may import inside its body (module docstring).
PLOT_MAY_IMPORT = ("reporting", "api")


def _plot_method_lines(path: Path) -> set[int]:
    """Lines of the imports inside a method named ``plot`` (a def directly in a class)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    lines = set()
    for cls in ast.walk(tree):
        if not isinstance(cls, ast.ClassDef):
            continue
        for fn in cls.body:
            if isinstance(fn, ast.FunctionDef) and fn.name == "plot":
                lines |= {
                    n.lineno for n in ast.walk(fn) if isinstance(n, ast.Import | ast.ImportFrom)
                }
    return lines


ALL_FILES = sorted(PKG.rglob("*.py"))
LAYERED = [p for p in ALL_FILES if _layer(_module(p)) is not None]


def test_the_source_tree_is_found():
    # a wrong SRC would make every check below pass on nothing
    assert len(LAYERED) > 40 and {_layer(_module(p)) for p in LAYERED} == set(RANK)


def test_imports_go_down_the_layers_only():
    bad = []
    for path in LAYERED:
        mod = _module(path)
        here = _layer(mod)
        in_plot = _plot_method_lines(path)
        for line, name, _ in _imports(path):
            there = _layer(name)
            if there is not None and RANK[there] > RANK[here]:
                if line in in_plot and there in PLOT_MAY_IMPORT:
                    continue  # a result's picture, imported only when drawn (module doc)
                bad.append(f"{mod}:{line} ({here}) imports {name} ({there})")
    assert not bad, "\n".join(bad)


def test_only_plot_methods_may_import_reporting():
    """The exception is exactly a function-level import in a class's ``plot`` method: the
    same import at module level or in another function is still reported."""
    import tempfile

    code = (
        "import airbearing.reporting.html\n"
        "def plot():\n    import airbearing.reporting.html\n"
        "class R:\n    def draw(self):\n        import airbearing.reporting.html\n"
        "    def plot(self):\n        import airbearing.reporting.html\n"
    )
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "m.py"
        path.write_text(code)
        assert _plot_method_lines(path) == {8}
        assert [line for line, _, _ in _imports(path)] == [1, 3, 6, 8]


@pytest.mark.parametrize("layer", ["design", "models", "io"])
def test_lower_layers_never_import_analysis(layer):
    """The issue's grep: nothing under design/, models/, io/ names airbearing.analysis."""
    hits = [
        f"{p.relative_to(SRC)}:{i}"
        for p in sorted((PKG / layer).rglob("*.py"))
        for i, text in enumerate(p.read_text().splitlines(), 1)
        if re.match(r"\s*(from|import)\s+airbearing(\.analysis\b|\s+import\s+analysis\b)", text)
    ]
    assert not hits, hits


def test_matplotlib_only_at_module_level_in_reporting():
    bad = [
        f"{_module(p)}:{line}"
        for p in ALL_FILES
        if _layer(_module(p)) != "reporting"
        for line, name, at_top in _imports(p)
        if at_top and name.split(".")[0] == "matplotlib"
    ]
    assert not bad, bad


@pytest.mark.slow
def test_algorithm_modules_do_not_load_matplotlib_on_import():
    """Import every module of io/, models/, design/ and analysis/ in a fresh interpreter,
    one after the other, and name the first that brings matplotlib in."""
    modules = [
        _module(p) for p in LAYERED if _layer(_module(p)) in ("io", "models", "design", "analysis")
    ]
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}:\n"
        "    importlib.import_module(m)\n"
        "    if 'matplotlib' in sys.modules:\n"
        "        print(m)\n"
        "        break\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "", f"{done.stdout.strip()} imports matplotlib"


def test_no_library_code_knows_the_example_data():
    """Issue 12 item 5: the demo and the tests simulate their own data; the library never
    names the shared example folder."""
    hits = [
        f"{p.relative_to(SRC)}:{i}"
        for p in ALL_FILES
        for i, text in enumerate(p.read_text().splitlines(), 1)
        if re.search(r"shared[/\\\\]+data|\.\./shared|/work/shared", text)
    ]
    assert not hits, hits
