"""One grammar for every command, and the old spellings that still work for one release.

The grammar (docs/reference/cli.md):

- the testbed is the first positional argument wherever a command takes one;
- ``-o/--out PATH`` is the main artefact, ``--json PATH`` the JSON summary,
  ``--report PATH`` the HTML report, ``--write-testbed PATH`` a testbed file;
- seeds say what they seed: ``--noise-seed`` (sensor noise of a simulation),
  ``--split-seed`` (the held-out window split of ``discrepancy``).

:func:`rewrite` turns an old spelling into the new one before the parser sees it and
says so in one ``airbearing: deprecated: ...`` line on stderr, so scripts written for
the previous release keep running. Light to import (no numpy, no typer).
"""

from __future__ import annotations

__all__ = ["RENAMED", "TESTBED_OPTION", "GLOBAL_FLAGS", "rewrite", "command_path", "TYPED"]

#: New spelling -> old spelling the user typed, of the last :func:`rewrite` (so a
#: message names the option as typed: ``--log dep.txt: ...``, not ``-o dep.txt``).
TYPED: dict[str, str] = {}

#: Old option spelling -> new one, per command path.
RENAMED: dict[tuple[str, ...], dict[str, str]] = {
    ("simulate",): {"--output": "--out", "--seed": "--noise-seed"},
    ("balance",): {"--log": "--out", "--output": "--out", "--seed": "--noise-seed"},
    ("demo",): {"--output": "--out"},
    ("discrepancy",): {"--seed": "--split-seed"},
    ("cmg", "envelope"): {"--output": "--out"},
    ("testbed", "export"): {"--output": "--out"},
    ("report",): {"--output": "--out"},
    ("campaign",): {"--output": "--out"},
    ("log", "import"): {"--output": "--out"},
    ("log", "plot"): {"--output": "--out"},
}
#: Commands whose testbed was an option ``--testbed X`` and is now the first positional.
TESTBED_OPTION: tuple[tuple[str, ...], ...] = (("log", "import"), ("log", "check"), ("log", "plot"))
#: Options of ``airbearing`` itself (before the command).
GLOBAL_FLAGS = ("--quiet", "-q", "--debug", "--verbose", "-v", "--version", "--help", "-h")
#: Global switches that may also be typed after the command (moved before it).
_ANYWHERE = ("--quiet", "-q", "--debug", "--verbose", "-v")
_GROUPS = ("log", "cmg", "testbed")
_NOTE = "the old spelling works until the next release"


def command_path(argv: list[str]) -> tuple[tuple[str, ...], int]:
    """The command words of ``argv`` (``("log", "check")``) and the index after them."""
    i = 0
    while i < len(argv) and argv[i] in GLOBAL_FLAGS:
        i += 1
    if i >= len(argv):
        return (), i
    if argv[i] in _GROUPS and i + 1 < len(argv) and not argv[i + 1].startswith("-"):
        return (argv[i], argv[i + 1]), i + 2
    return (argv[i],), i + 1


def rewrite(argv: list[str]) -> tuple[list[str], list[str]]:
    """``argv`` in the current grammar, and one deprecation line per old spelling used.

    Global switches typed after the command (``--quiet``, ``-q``, ``--verbose``,
    ``-v``, ``--debug``) move before it. Examples: ``simulate cmg-yaw --seed 3`` ->
    ``... --noise-seed 3``; ``simulate cmg-yaw -q`` -> ``-q simulate cmg-yaw``; ``log check
    LOG --testbed TB`` -> ``log check TB LOG``; ``testbed list --json`` (a switch) ->
    ``testbed list --json -`` (JSON on stdout).
    """
    TYPED.clear()
    path, start = command_path(argv)
    if not path:
        return list(argv), []
    head, rest = list(argv[:start]), list(argv[start:])
    notes: list[str] = []
    cmd = " ".join(path)
    renamed = RENAMED.get(path, {})
    out: list[str] = []
    testbed: str | None = None
    i = 0
    while i < len(rest):
        tok = rest[i]
        if tok == "--":
            out.extend(rest[i:])
            break
        name, eq, value = tok.partition("=")
        if tok in _ANYWHERE:  # `airbearing simulate cmg-yaw -q`: a global switch
            head.insert(0, tok)
            i += 1
            continue
        if path in TESTBED_OPTION and name == "--testbed":
            if eq:
                testbed = value
            elif i + 1 < len(rest):
                testbed = rest[i + 1]
                i += 1
            else:
                out.append(tok)  # let the parser say what is missing
                i += 1
                continue
            notes.append(
                f"deprecated: '{cmd} --testbed TESTBED' is now '{cmd} TESTBED ...' "
                f"(the testbed first); {_NOTE}"
            )
            i += 1
            continue
        if name in renamed:
            new = renamed[name]
            notes.append(f"deprecated: '{cmd} {name}' is now '{new}'; {_NOTE}")
            TYPED[new] = name
            out.append(new + (f"={value}" if eq else ""))
            i += 1
            continue
        if path == ("testbed", "list") and tok == "--json":
            nxt = rest[i + 1] if i + 1 < len(rest) else None
            if nxt is None or nxt.startswith("-") and nxt != "-":
                notes.append(
                    f"deprecated: '{cmd} --json' (a switch) is now '--json PATH' "
                    f"('--json -' for stdout); {_NOTE}"
                )
                out.extend(["--json", "-"])
                i += 1
                continue
        out.append(tok)
        i += 1
    if testbed is not None:
        out.insert(0, testbed)
    return head + out, list(dict.fromkeys(notes))
