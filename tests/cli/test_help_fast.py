"""``airbearing CMD --help`` prints the parser's own help without the parser's start-up cost."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import typer.main

from airbearing.cli import _register, app, fast_help


def _paths() -> list[list[str]]:
    _register()
    group = typer.main.get_command(app)
    out: list[list[str]] = [[]]
    for name, cmd in group.commands.items():
        out.append([name])
        out += [[name, sub] for sub in getattr(cmd, "commands", {}) or {}]
    return out


@pytest.mark.parametrize("path", _paths(), ids=lambda p: " ".join(p) or "airbearing")
def test_fast_help_is_the_parsers_help(path, capsys):
    # typer's own output: the app called directly, past main()'s fast path
    try:
        app(args=[*path, "--help"], prog_name="airbearing", standalone_mode=False)
    except SystemExit:
        pass
    parser = capsys.readouterr().out
    assert fast_help([*path, "--help"]) + "\n" == parser
    assert fast_help([*path, "-h"]) + "\n" == parser


def test_help_with_other_options_is_left_to_the_parser():
    # a typo beside --help is the parser's to report; not a help request: nothing
    assert fast_help(["simulate", "--duratoin", "3", "--help"]) is None
    assert fast_help(["simulate", "cmg-yaw"]) is None
    assert fast_help(["nosuch", "--help"]) is None
    assert fast_help(["simulate", "--", "--help"]) is None


def test_command_help_loads_no_pydantic():
    # typer coerces parameters through pydantic: ~0.25 s of a 0.5 s `CMD --help`
    code = (
        "import sys, json\n"
        "sys.argv = ['airbearing', 'discrepancy', '--help']\n"
        "from airbearing.cli import main\n"
        "main()\n"
        "print(json.dumps([m for m in ('pydantic', 'airbearing.cli.demo') if m in sys.modules]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
