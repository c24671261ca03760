"""Every ``airbearing`` command shown in the README runs.

Commands are the lines of the README's ```sh (or ```console) fenced blocks that call
``airbearing`` (also inside ``a && b`` chains, ``.venv/bin/airbearing``, a ``$`` prompt,
``\\`` continuations). They run one after the other in one temporary folder (so a command
may use a file an earlier one wrote), as new processes, with short durations where an
option allows: ``--duration`` at most :data:`MAX_DURATION` s, ``demo`` with ``--quick``.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
#: s, longest run a README command gets here (the README's own numbers stay as written).
MAX_DURATION = 20.0


def readme_commands(text: str) -> list[list[str]]:
    """The ``airbearing`` commands of the README's shell blocks, as argument lists."""
    commands = []
    for block in re.findall(r"```(?:sh|bash|console|shell)[^\n]*\n(.*?)```", text, re.S):
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
        "```python\nairbearing.x()\n```\n"
    )
    cmds = readme_commands(text)
    assert cmds == [["demo", "--out", "d"], ["simulate", "cmg-yaw", "--duration", "3600", "-o",
                                              "log.csv"]]  # fmt: skip
    assert shortened(cmds[1])[3] == "20" and shortened(cmds[0])[-1] == "--quick"


COMMANDS = readme_commands(README.read_text()) if README.is_file() else []


@pytest.mark.slow
def test_readme_commands_run(tmp_path):
    assert COMMANDS, "the README shows no airbearing command in a ```sh block"
    for args in COMMANDS:
        args = shortened(args)
        out = subprocess.run(
            [sys.executable, "-m", "airbearing", "--quiet", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert out.returncode == 0, f"airbearing {' '.join(args)}: {out.stderr[-1500:]}"
