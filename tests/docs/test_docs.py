"""The documentation: its examples run, its navigation is whole, CI builds it.

- The Examples sections of the public functions and classes the front door exposes run in
  ``test_docstrings.py``; here, those of the other functions of :data:`DOCTEST_MODULES`.
- The tutorials' ```python blocks run, from a folder holding a copy of ``examples/``.
- Every page in ``mkdocs.yml``'s navigation exists; ``docs/FORMATS.md`` is the shared
  contract byte for byte when the shared copy is beside the repository.
- ``.ci/run`` runs the README's test command and its documentation build, verbatim.

The site itself (``mkdocs build --strict``) is built by ``.ci/run``, not here: it needs the
``docs`` extra, and the test suite must not depend on it.
"""

from __future__ import annotations

import doctest
import importlib
import re
import shutil
from pathlib import Path

import matplotlib.pyplot as plt
import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"

#: Modules with docstring Examples on functions that are not front-door names (those of
#: ``airbearing.__all__`` run once, in ``test_docstrings.py``).
DOCTEST_MODULES = [
    "airbearing.design.loops",
    "airbearing.analysis.identification.options",  # columns_used
]
#: Tutorials and how-to pages whose Python blocks run here (the campaign tutorial starts a
#: Dask cluster on a file the reader writes: its commands are tested in test_campaign*).
RUN_PAGES = [
    "tutorials/raw-log-to-effect.md",
    "tutorials/slew-tune-report.md",
    "tutorials/identify-platform.md",
    "how-to/python.md",
    "how-to/simulate-passive-and-artefacts.md",
]


@pytest.mark.parametrize("name", DOCTEST_MODULES)
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    import airbearing as ab

    monkeypatch.chdir(tmp_path)  # an example that writes a file writes it here
    module = importlib.import_module(name)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=flags)
    public = {f"{name}.{n}" for n in ab.__all__}
    tests = [
        t
        for t in finder.find(module)
        if t.examples and not any(t.name == p or t.name.startswith(p + ".") for p in public)
    ]
    assert tests, f"{name}: no Examples section"
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} doctest example(s) failed (see above)"


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"```python[^\n]*\n(.*?)```", text, re.S)


@pytest.mark.slow
@pytest.mark.parametrize("page", RUN_PAGES)
def test_page_python_blocks_run(page, tmp_path, monkeypatch, library_once):
    """Each block runs as a script (``__name__ == "__main__"``, a fresh namespace) in this
    interpreter: a new one per block paid ~3 s of imports and model building each; the
    README's blocks (test_readme_commands.py) are the ones run in a new interpreter. A
    tuning or stability report a page asks for with the arguments another test asked for
    is that test's (``library_once``, tests/conftest.py: once per test run)."""
    blocks = _python_blocks((DOCS / page).read_text())
    assert blocks, f"{page}: no python block"
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    for i, code in enumerate(blocks):
        try:
            exec(compile(code, f"{page} block {i}", "exec"), {"__name__": "__main__"})
        except Exception as e:
            raise AssertionError(f"{page} block {i}:\n{code}") from e
        finally:
            plt.close("all")


def _nav_pages(node) -> list[str]:
    if isinstance(node, str):
        return [node] if node.endswith(".md") else []
    if isinstance(node, dict):
        return [p for v in node.values() for p in _nav_pages(v)]
    if isinstance(node, list):
        return [p for v in node for p in _nav_pages(v)]
    return []


def test_every_nav_page_exists_and_no_page_is_orphaned():
    text = (ROOT / "mkdocs.yml").read_text()
    nav = re.findall(r":\s*([\w./-]+\.md)\s*$", text, re.M)
    assert "index.md" in nav and "FORMATS.md" in nav and "changelog.md" in nav
    missing = [p for p in nav if not (DOCS / p).is_file()]
    assert not missing, f"in mkdocs.yml's nav but not in docs/: {missing}"
    # pages written by others land in docs/ first; the nav must take them in (a file that
    # another page includes whole, `--8<-- "docs/..."`, is part of that page instead)
    included = {
        m for p in DOCS.rglob("*.md") for m in re.findall(r'--8<--\s+"docs/([^"]+)"', p.read_text())
    }
    orphans = sorted(
        rel
        for rel in (str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md"))
        if rel not in nav and rel not in included
    )
    assert not orphans, f"docs pages not in mkdocs.yml's nav: {orphans}"


def test_formats_is_the_shared_contract():
    shared = ROOT.parent / "shared" / "FORMATS.md"
    if not shared.is_file():
        pytest.skip("no shared FORMATS.md beside the repository")
    assert (DOCS / "FORMATS.md").read_bytes() == shared.read_bytes()


def test_ci_runs_the_readme_commands():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    test_cmd = (
        'python3 -m venv .venv && .venv/bin/pip install -q --no-compile -e ".[test]"'
        " && .venv/bin/python -m pytest"
    )
    docs_cmd = (
        '.venv/bin/pip install -q -e ".[docs]" && .venv/bin/mkdocs build --strict --site-dir site'
    )
    for cmd in (test_cmd, docs_cmd):
        assert cmd in readme, f"the README no longer shows: {cmd}"
        assert any(line.strip() == cmd for line in ci.splitlines()), f".ci/run does not run: {cmd}"
    assert "chromium" in ci and "CI=" in ci


def test_changelog_is_in_the_site():
    assert (DOCS / "changelog.md").read_text().strip() == '--8<-- "CHANGELOG.md"'
    assert (ROOT / "CHANGELOG.md").read_text().startswith("# Changelog")


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for k in range(len(parts), 1, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        try:
            for name in parts[k:]:
                obj = getattr(obj, name)
        except AttributeError:
            return False
        return True
    return False


def test_docs_name_only_what_exists():
    """Every `airbearing.x.y` / `io.x.y` / `ab.name` the pages and README name exists (the
    old README and internals.md had drifted from the code)."""
    import airbearing as ab

    pattern = r"`((?:airbearing\.)?(?:io|models|design|analysis|reporting|cli|api)\.[\w.]+)"
    pages = [p for p in DOCS.rglob("*.md") if p.name != "FORMATS.md"] + [ROOT / "README.md"]
    bad = []
    for page in pages:
        text = page.read_text()
        for name in set(re.findall(pattern, text)):
            full = name if name.startswith("airbearing.") else f"airbearing.{name}"
            if not _resolves(full):
                bad.append(f"{page.relative_to(ROOT)}: {name}")
        bad += [
            f"{page.relative_to(ROOT)}: ab.{n}"
            for n in set(re.findall(r"\bab\.(\w+)\(", text))
            if n not in ab.__all__
        ]
    assert not bad, bad
