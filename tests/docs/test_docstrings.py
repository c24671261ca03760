"""Every public function and class of ``import airbearing as ab`` has a numpydoc docstring
with a runnable example (the idea of python-control's ``control/tests/docstrings_test.py``).

``test_docstring_sections`` parses each docstring with ``numpydoc.docscrape`` and checks:
a summary; an ``Examples`` section with ``>>>`` lines; a ``Parameters`` section that names
every parameter of the signature and nothing else (for a class, its constructor's
parameters, documented under ``Parameters`` or ``Attributes``); a ``Returns`` (or
``Yields``) section on a function that returns something; a ``Raises`` section on one whose
own body raises ``InputError``. The public methods of the public classes (``to_json``,
``plot``, ``summary``...) get the same checks except the example (the class's example
shows them).

``test_examples_run`` runs each public object's examples with ``doctest`` (ELLIPSIS and
NORMALIZE_WHITESPACE; each example imports what it uses, nothing is pre-loaded), in an
empty working folder so an example that writes a file writes it there.

The examples are cheap (a few seconds of simulated log at 20 Hz, a small model, one
candidate effect): this file takes about 15 s of CPU on one core with the compiled-function
cache warm, 20 s cold, most of it the first shooting fits and the imports. ``SKIPPED``
lists the only names whose example has a line marked ``# doctest: +SKIP``, one line each
(the expensive call, its output shown), with the reason: ``tune`` and ``TuningResult`` (the
gain search), ``stability_report`` and ``report_for_loop`` (every corner, the responses,
the figures), ``two_step`` and ``TwoStepResult`` (three balancing steps and up to six
identifications), ``run_demo`` (every demo section) and ``open_client`` (a local Dask
cluster). ``test_skipped_examples_are_listed`` fails if another name gains a skipped line
or one of these a second, so the list cannot grow silently.

``SEED001_GAINS`` and ``__version__`` are constants, not functions or classes: not checked.
"""

from __future__ import annotations

import ast
import doctest
import inspect
import re
import textwrap
import warnings

import pytest
from numpydoc.docscrape import NumpyDocString

import airbearing as ab

#: Names whose example has a ``+SKIP`` line, and why that line cannot run in the suite.
SKIPPED: dict[str, str] = {
    "tune": "the search checks a few hundred designs at every corner (10-40 s)",
    "TuningResult": "made only by tune (10-40 s)",
    "stability_report": "every corner, the responses and the figures (15-30 s)",
    "report_for_loop": "the same report as stability_report (15-30 s)",
    "two_step": "three balancing steps, up to six identifications (8-12 s on short runs)",
    "TwoStepResult": "made only by two_step (8-12 s)",
    "run_demo": "every section of the demo report (a minute even quick)",
    "open_client": "a local Dask cluster starts worker processes (seconds, and CPU the suite's"
    " other workers use)",
}
#: Names whose example compiles C (skipped without a compiler, failed on CI without one).
NEEDS_COMPILER = {"ReplayCheck"}

PUBLIC = sorted(
    name
    for name in ab.__all__
    if inspect.isclass(getattr(ab, name)) or inspect.isfunction(getattr(ab, name))
)


def _parsed(obj, where: str) -> NumpyDocString:
    doc = inspect.getdoc(obj)
    assert doc, f"{where}: no docstring"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an unknown section or a bad layout is a failure
        return NumpyDocString(doc)


def _documented(items) -> set[str]:
    """The names of a Parameters/Attributes section (``a, b : float`` names two)."""
    names = set()
    for item in items:
        for part in item.name.split(","):
            names.add(part.strip().lstrip("*"))
    return names


def _own_parameters(func, skip_first: bool) -> list[str]:
    params = list(inspect.signature(func).parameters.values())
    if skip_first:
        params = params[1:]
    return [p.name for p in params if not p.name.startswith("_")]  # private: not documented


def _raises_input_error(func) -> bool:
    try:
        source = inspect.getsource(func)
    except (OSError, TypeError):
        return False
    return re.search(r"^\s*raise InputError\b", source, flags=re.M) is not None


def _returns_something(func) -> bool:
    """Annotated with a return type, or (no annotation) a ``return <value>`` of its own."""
    annotation = inspect.signature(func).return_annotation
    if annotation is not inspect.Signature.empty:
        return annotation not in (None, "None")
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    except (OSError, TypeError, SyntaxError):
        return False
    own = [tree.body[0]]
    found = False
    while own:  # its own statements, not those of the functions it defines
        node = own.pop()
        if isinstance(node, ast.Return) and node.value is not None:
            found = True
        own += [
            child
            for child in ast.iter_child_nodes(node)
            if not isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
        ]
    return found


def _check_function(func, where: str, doc: NumpyDocString, skip_first: bool) -> list[str]:
    problems = []
    signature = set(_own_parameters(func, skip_first))
    documented = _documented(doc["Parameters"])
    if missing := sorted(signature - documented):
        problems.append(f"{where}: parameters not documented: {missing}")
    if extra := sorted(documented - signature):
        problems.append(f"{where}: documented but not in the signature: {extra}")
    if _returns_something(func) and not (doc["Returns"] or doc["Yields"]):
        problems.append(f"{where}: no Returns section")
    if _raises_input_error(func) and not doc["Raises"]:
        problems.append(f"{where}: raises InputError but has no Raises section")
    return problems


def _public_methods(cls) -> list[tuple[str, object]]:
    """Methods and properties the class itself defines (not inherited, not private)."""
    return [
        (name, member)
        for name, member in vars(cls).items()
        if not name.startswith("_") and (inspect.isfunction(member) or isinstance(member, property))
    ]


@pytest.mark.parametrize("name", PUBLIC)
def test_docstring_sections(name):
    obj = getattr(ab, name)
    doc = _parsed(obj, name)
    problems = []
    if not doc["Summary"]:
        problems.append(f"{name}: no one-line summary")
    if not any(line.lstrip().startswith(">>>") for line in doc["Examples"]):
        problems.append(f"{name}: no Examples section with >>> lines")
    if inspect.isclass(obj):
        if issubclass(obj, BaseException):
            return  # an exception: its constructor is BaseException's (a message)
        signature = set(_own_parameters(obj, skip_first=False))
        documented = _documented(doc["Parameters"])
        attributes = _documented(doc["Attributes"])
        if missing := sorted(signature - documented - attributes):
            problems.append(f"{name}: constructor parameters not documented: {missing}")
        if extra := sorted(documented - signature):
            problems.append(f"{name}: Parameters not in the constructor: {extra}")
        for method_name, member in _public_methods(obj):
            where = f"{name}.{method_name}"
            if isinstance(member, property):
                if not inspect.getdoc(member):
                    problems.append(f"{where}: property without a docstring")
                continue
            method_doc = _parsed(member, where)
            is_static = isinstance(inspect.getattr_static(obj, method_name), staticmethod)
            problems += _check_function(member, where, method_doc, skip_first=not is_static)
    else:
        problems += _check_function(obj, name, doc, skip_first=False)
    assert not problems, "\n".join(problems)


def _examples(name: str) -> list[doctest.DocTest]:
    obj = getattr(ab, name)
    finder = doctest.DocTestFinder(recurse=inspect.isclass(obj), exclude_empty=True)
    tests = finder.find(obj, f"airbearing.{name}", globs={})
    # a class's finder also walks attributes defined elsewhere: keep the class's own
    return [t for t in tests if t.examples and t.name.startswith(f"airbearing.{name}")]


@pytest.mark.parametrize("name", PUBLIC)
def test_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if name in NEEDS_COMPILER:
        from c_compiler import c_compiler

        c_compiler()
    import matplotlib

    matplotlib.use("Agg")
    tests = _examples(name)
    assert any(t.name == f"airbearing.{name}" for t in tests), f"{name}: no example to run"
    runner = doctest.DocTestRunner(
        optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False
    )
    report = []
    for test in tests:
        runner.run(test, out=report.append, clear_globs=True)
    assert runner.failures == 0, "".join(report)


def test_skipped_examples_are_listed():
    """Only the names of SKIPPED skip, each one line (the expensive call) and no more."""
    skipping = [
        name
        for name in PUBLIC
        for test in _examples(name)
        for example in test.examples
        if example.options.get(doctest.SKIP)
    ]
    assert sorted(set(skipping)) == sorted(SKIPPED), "update SKIPPED and its reasons"
    assert len(skipping) == len(SKIPPED), f"more than one skipped line: {sorted(skipping)}"
