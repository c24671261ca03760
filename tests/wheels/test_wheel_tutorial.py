"""The reaction-wheel tutorial (docs/tutorials/reaction-wheel-rig.md), run as written.

Every ``sh`` block's commands run in a temporary folder, in order; every line of a
``text`` block must be printed by the command before it. A change that moves a printed
number fails here, and the tutorial is updated with the reason.
"""

import re
import shlex
from pathlib import Path

import pytest
from cli_run import run

TUTORIAL = Path(__file__).parents[2] / "docs" / "tutorials" / "reaction-wheel-rig.md"


def _steps():
    """``(commands, printed lines)`` of each ``sh`` block, the ``text`` block after it."""
    text = TUTORIAL.read_text()
    blocks = re.findall(r"```(sh|text)\n(.*?)```", text, flags=re.S)
    steps = []
    for kind, body in blocks:
        lines = [ln for ln in body.strip().splitlines() if ln.strip()]
        if kind == "sh":
            steps.append((lines, []))
        else:
            steps[-1][1].extend(lines)
    return steps


def test_the_tutorial_has_its_steps():
    steps = _steps()
    assert len(steps) == 6 and all(cmd[0].startswith("airbearing ") for cmd, _ in steps)
    assert sum(len(printed) for _, printed in steps) >= 4


@pytest.mark.slow  # a tuning, a 60 s slew, a discrepancy search and a C compile: ~40 s
def test_the_tutorial_prints_what_it_says(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for commands, printed in _steps():
        out = ""
        for line in commands:
            argv = shlex.split(line)
            assert argv[0] == "airbearing"
            assert run(["--quiet", *argv[1:]]) == 0, line
            got = capsys.readouterr()
            out += got.out + got.err
        for want in printed:
            assert want.strip() in out, f"{commands[-1]!r} did not print {want!r}:\n{out}"
