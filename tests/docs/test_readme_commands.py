"""Every command and Python block shown in the README runs.

Commands are the lines of the README's ```sh (or ```console) fenced blocks that call
``airbearing`` (also inside ``a && b`` chains, ``.venv/bin/airbearing``, a ``$`` prompt,
``\\`` continuations). They run one after the other in one temporary folder holding a copy
of ``examples/`` (so a command may use a file an earlier one wrote, as in a fresh clone),
in-process (``airbearing``'s ``main``, as ``tests/cli_run.py`` calls it; the demo below
runs as a new process), with short durations where an option
allows: ``--duration`` at most :data:`MAX_DURATION` s. Some blocks are run elsewhere, each
exactly once per session: the demo (``tests/reporting/test_demo.py``, from the ``demo_run``
fixture, which runs the README's demo command with ``--quick``), the worked example
(``tests/docs/test_worked_example.py``, which also checks its answer) and the ``gains`` and
``report`` commands on ``cmg-yaw`` (``tests/reporting/test_stability_report.py``, as
written, which checks their outputs). The README's ```python blocks run in a new
interpreter from the repository's folder.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_run import run
from conftest import DEMO_ARGS, README_GAINS_ARGS, README_REPORT_ARGS

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
#: s, longest run a README command gets here (the README's own numbers stay as written).
MAX_DURATION = 20.0
#: The heading of the README's worked example (tests/docs/test_worked_example.py runs its block).
WORKED_EXAMPLE = "## From a lab's raw log to a named effect"

SH_BLOCK = r"```(?:sh|bash|console|shell)[^\n]*\n(.*?)```"


def commands_of(block: str) -> list[list[str]]:
    """The ``airbearing`` commands of one shell block, as argument lists."""
    commands = []
    joined = re.sub(r"\\\n\s*", " ", block)
    for line in joined.splitlines():
        line = line.strip()
        if line.startswith("$ "):
            line = line[2:]
        if not line or line.startswith("#"):
            continue
        for part in line.split("&&"):
            words = shlex.split(part, comments=True)
            if words and Path(words[0]).name == "airbearing":
                commands.append(words[1:])
    return commands


def readme_commands(text: str) -> list[list[str]]:
    """The ``airbearing`` commands of every shell block of ``text``."""
    return [c for block in re.findall(SH_BLOCK, text, re.S) for c in commands_of(block)]


def section(text: str, heading: str) -> str:
    """The text under ``heading`` up to the next heading of the same or a higher level."""
    start = text.index(heading)
    level = heading.split(" ")[0]
    nxt = re.search(rf"^#{{1,{len(level)}}} ", text[start + len(heading) :], re.M)
    return text[start : start + len(heading) + (nxt.start() if nxt else len(text))]


def worked_example_commands(text: str) -> list[list[str]]:
    """The commands of the worked example's shell block."""
    return readme_commands(section(text, WORKED_EXAMPLE))


def python_blocks(text: str) -> list[str]:
    return re.findall(r"```python[^\n]*\n(.*?)```", text, re.S)


def shortened(args: list[str]) -> list[str]:
    """``args`` with ``--duration`` capped and the demo quick."""
    out = list(args)
    for i, a in enumerate(out[:-1]):
        if a == "--duration":
            try:
                out[i + 1] = f"{min(float(out[i + 1]), MAX_DURATION):g}"
            except ValueError:
                pass
    if out and out[0] == "demo" and "--quick" not in out:
        out.append("--quick")
    return out


def test_extraction():
    text = (
        "```sh\npython3 -m venv .venv && .venv/bin/airbearing demo --out d\n"
        "$ airbearing simulate cmg-yaw \\\n  --duration 3600 -o log.csv  # a comment\n```\n"
        "```python\nairbearing.x()\n```\n## A\n```sh\nairbearing a\n```\n### B\nx\n## C\n"
    )
    cmds = readme_commands(text)
    assert cmds[:2] == [["demo", "--out", "d"], ["simulate", "cmg-yaw", "--duration", "3600",
                                                 "-o", "log.csv"]]  # fmt: skip
    assert shortened(cmds[1])[3] == "20" and shortened(cmds[0])[-1] == "--quick"
    assert readme_commands(section(text, "## A")) == [["a"]]
    assert python_blocks(text) == ["airbearing.x()\n"]


TEXT = README.read_text() if README.is_file() else ""
COMMANDS = readme_commands(TEXT)


def test_readme_demo_is_the_suites_demo_run():
    """The README's first command is the demo; the suite's one demo run runs it quick."""
    demos = [shortened(c) for c in COMMANDS if c and c[0] == "demo"]
    assert demos == [DEMO_ARGS], demos


def test_readme_tuning_is_the_stability_report_tests_run():
    """The README's gains-then-report pair is the one test_stability_report.py runs."""
    i = COMMANDS.index(README_GAINS_ARGS)
    assert COMMANDS[i + 1] == README_REPORT_ARGS, COMMANDS[i : i + 2]


@pytest.mark.slow
def test_readme_commands_run(tmp_path, monkeypatch, capsys):
    assert COMMANDS, "the README shows no airbearing command in a ```sh block"
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    skip = [c for c in COMMANDS if c[0] == "demo"] + worked_example_commands(TEXT)
    skip += [README_GAINS_ARGS, README_REPORT_ARGS]
    for args in COMMANDS:
        if args in skip:
            continue
        args = shortened(args)
        code = run(["--quiet", *args])
        err = capsys.readouterr().err
        assert code == 0, f"airbearing {' '.join(args)}: {err[-1500:]}"
        assert "deprecated" not in err, f"old spelling in the README: {err}"


@pytest.mark.slow
@pytest.mark.parametrize("index", range(len(python_blocks(TEXT))))
def test_readme_python_blocks_run(index):
    code = python_blocks(TEXT)[index]
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=900
    )
    assert out.returncode == 0, f"README python block {index}:\n{code}\n{out.stderr[-2000:]}"
