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

Imports stand at the top of a module. Allowed inside a function: the CLI's command modules
(``cli/``: ``airbearing --help`` must not load the numerical libraries), a result's ``plot``
method, and the counts of :data:`FUNCTION_IMPORTS` (each module's imports inside functions
as they stand; a module may lower its count, never raise it, and a module not listed has
none). No private name (``_x``) is imported from another package, except
:data:`PRIVATE_IMPORTS`.
"""

from __future__ import annotations

import ast
import functools
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


@functools.cache
def _nodes(path: Path) -> tuple[list[ast.AST], list[ast.ClassDef], set[int]]:
    """``(import statements, classes, ids of the nodes that run at import)`` of a file,
    parsed and walked once per session (every check below reads the same files)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top = {id(n) for n in tree.body}
    # imports under a module-level `if`/`try` run at import too
    for n in tree.body:
        if isinstance(n, ast.If | ast.Try):
            top |= {id(c) for c in ast.walk(n)}
    imports, classes = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            imports.append(node)
        elif isinstance(node, ast.ClassDef):
            classes.append(node)
    return imports, classes, top


def _imports(path: Path) -> list[tuple[int, str, bool]]:
    """``(line, imported module, at module level)`` for every absolute import in a file."""
    nodes, _, top = _nodes(path)
    out = []
    for node in nodes:
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


@functools.cache
def _plot_method_lines(path: Path) -> set[int]:
    """Lines of the imports inside a method named ``plot`` (a def directly in a class)."""
    lines = set()
    for cls in _nodes(path)[1]:
        for fn in cls.body:
            if isinstance(fn, ast.FunctionDef) and fn.name == "plot":
                lines |= {
                    n.lineno for n in ast.walk(fn) if isinstance(n, ast.Import | ast.ImportFrom)
                }
    return lines


ALL_FILES = sorted(PKG.rglob("*.py"))
LAYERED = [p for p in ALL_FILES if _layer(_module(p)) is not None]


#: Imports inside functions outside cli/ and plot methods, per module (module docstring):
#: lazy imports of pandas, cvxpy, scipy.stats, statsmodels or dask that keep a light import
#: light (``import airbearing`` and the CLI's start-up), and imports that break a cycle.
#: The list can only shrink: move an import to the top and lower (or drop) its count.
FUNCTION_IMPORTS = {
    "analysis.balancing.drift": 1,
    "analysis.balancing.transient": 1,
    "analysis.campaign.adapters": 6,
    "analysis.campaign.child": 1,
    "analysis.campaign.results": 2,
    "analysis.campaign.runner": 3,
    "analysis.campaign.studies": 4,
    "analysis.discrepancy.adequacy": 2,  # statsmodels acovf, q_stat: ljung_box_p
    "analysis.discrepancy.consistency": 1,
    "analysis.discrepancy.honest": 1,
    "analysis.discrepancy.slow_torque": 1,  # scipy.stats: the F test
    "analysis.discrepancy.trial": 1,
    "analysis.identification.cmg_inertia": 2,
    "analysis.identification.convex": 1,
    "analysis.shooting.autoregressive": 5,
    "analysis.simulation.truth_accuracy": 1,  # scipy.signal: see test_discrepancy_search
    "analysis.shooting.constrained": 1,
    "analysis.shooting.errors": 3,
    "analysis.shooting.fit": 1,
    "analysis.shooting.measurement_noise": 3,
    "analysis.shooting.process_noise": 1,
    "api.logs": 1,
    "api.plot": 10,
    "design._control": 1,
    "design.margins": 1,
    "design.tuning.responses": 1,
    "io.coerce": 2,
    "io.log": 1,  # log_validate (pandas, 0.4-0.5 s): only a Log asked for its DataFrame
    "io.log_read": 3,  # pandas: only a log with other than float64 columns or a bad cell
    "io.quality_edges": 1,  # scipy.special at an edge test: 0.3-0.6 s of every log check
    "models.compiled": 1,
    "progress": 1,
    "reporting.campaign": 1,
    "reporting.demo": 4,
}

#: Private names imported from another package (module, name): to become public or move.
PRIVATE_IMPORTS: set = set()


def _function_level_imports(path: Path) -> list[int]:
    """Lines of the imports inside functions, other than inside a class's ``plot``."""
    nodes, _, top = _nodes(path)  # under a module-level `if`/`try`: run at import too
    in_plot = _plot_method_lines(path)
    return [n.lineno for n in nodes if id(n) not in top and n.lineno not in in_plot]


def test_imports_stand_at_the_top_of_modules():
    over = []
    for path in ALL_FILES:
        mod = _module(path).removeprefix("airbearing.")
        if mod == "cli" or mod.startswith("cli."):
            continue  # the command functions import the numerical libraries when run
        lines = _function_level_imports(path)
        if len(lines) > FUNCTION_IMPORTS.get(mod, 0):
            allowed = FUNCTION_IMPORTS.get(mod, 0)
            over.append(f"{mod}: {len(lines)} imports inside functions (allowed {allowed}): "
                        f"lines {lines}")  # fmt: skip
    assert not over, "\n".join(over)


def test_the_function_import_allowances_name_modules_that_exist():
    modules = {_module(p).removeprefix("airbearing.") for p in ALL_FILES}
    assert set(FUNCTION_IMPORTS) <= modules, set(FUNCTION_IMPORTS) - modules


def _package(module: str, path: Path) -> str:
    return module if path.name == "__init__.py" else module.rsplit(".", 1)[0]


def test_no_private_name_is_imported_from_another_package():
    found = set()
    for path in ALL_FILES:
        mod = _module(path)
        for n in _nodes(path)[0]:
            if not (isinstance(n, ast.ImportFrom) and n.level == 0 and n.module):
                continue
            if not n.module.startswith("airbearing."):
                continue
            is_pkg = (SRC / n.module.replace(".", "/")).is_dir()
            theirs = n.module if is_pkg else n.module.rsplit(".", 1)[0]
            if theirs == _package(mod, path):
                continue
            for a in n.names:
                if a.name.startswith("_") and not a.name.startswith("__"):
                    found.add((mod.removeprefix("airbearing."), a.name))
    assert found <= PRIVATE_IMPORTS, sorted(found - PRIVATE_IMPORTS)


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


def test_no_code_knows_the_example_data():
    """The demo and the tests simulate their own data: neither the library nor the tests
    nor the benchmarks name the shared example folder (benchmarks/check_cases.py checks
    cases given on its command line)."""
    repo = SRC.parent
    files = [*ALL_FILES, *(repo / "tests").rglob("*.py"), *(repo / "benchmarks").rglob("*.py")]
    me = Path(__file__).resolve()
    hits = [
        f"{p.relative_to(repo)}:{i}"
        for p in files
        if p.resolve() != me
        for i, text in enumerate(p.read_text().splitlines(), 1)
        if re.search(r'shared[/\\\\]+data|"shared"\s*/\s*"data"', text)
    ]
    assert not hits, hits
