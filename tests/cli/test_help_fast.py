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


def _fresh(code: str) -> object:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


LISTING = (
    "import json, typer.main\n"
    "from airbearing.cli import app\n"
    "print(json.dumps([sys.modules.get('airbearing.cli.balance') is not None,\n"
    "                  list(typer.main.get_command(app).commands)]))\n"
)


def test_a_command_registers_its_own_module_only_and_the_listing_keeps_its_order():
    # running `identify` builds only identify (the parser builds every registered
    # command's parameters); a later full registration lists in the usual order
    first = "import sys\nfrom airbearing.cli import _register\n_register()\n"
    one = (
        "import sys\nfrom airbearing.cli import _register, _register_for\n"
        "_register_for(['--quiet', 'identify', 'LOG'])\n"
        "assert 'airbearing.cli.balance' not in sys.modules\n"
        "_register()\n"
    )
    loaded, usual = _fresh(first + LISTING)
    assert loaded and usual[:2] == ["balance", "demo"] and usual[-3:] == ["cmg", "testbed", "log"]
    assert _fresh(one + LISTING) == [True, usual]


@pytest.mark.parametrize(
    ("args", "said"),
    [(["identfy", "X"], "Did you mean 'identify'?"), (["common", "X"], "No such command")],
)
def test_an_unknown_command_is_told_among_all_of_them(args, said):
    # a word that is no command (a typo, or one of the CLI's own helper modules): the
    # parser sees every command, so its message suggests the right one
    code = (
        "import sys, json, contextlib, io\n"
        "from airbearing.cli import main\n"
        "err = io.StringIO()\n"
        "with contextlib.redirect_stderr(err):\n"
        "    try:\n"
        f"        main({args!r})\n"
        "    except SystemExit as e:\n"
        "        code = e.code\n"
        "print(json.dumps([code, err.getvalue()]))\n"
    )
    code_, text = _fresh(code)
    assert code_ == 2 and said in text
