"""One grammar for every command: inputs never written, old spellings, help, log check's truth."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML

from airbearing.cli import _register, app
from airbearing.cli.grammar import rewrite

_register()


def _commands() -> dict[str, object]:
    """Every leaf command by its path ("log check"), from the registered app."""
    import typer.main

    out = {}

    def walk(cmd, prefix):
        subs = getattr(cmd, "commands", None)
        if subs:
            for name, sub in subs.items():
                walk(sub, [*prefix, name])
        else:
            out[" ".join(prefix)] = cmd

    walk(typer.main.get_command(app), [])
    return out


COMMANDS = _commands()


@pytest.fixture
def files(tmp_path):
    """One input file of each kind a command reads."""
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.builtins import builtin_toml
    from airbearing.io.log import write_log
    from airbearing.io.testbed import load_testbed

    d = tmp_path
    (d / "tb.toml").write_bytes(builtin_toml("cmg-yaw"))
    write_log(slew(load_testbed("cmg-yaw"), duration=2.0, ideal=True).log, d / "log.csv")
    write_log(slew(load_testbed("cmg-yaw"), duration=2.0, ideal=True).log, d / "held.csv")
    (d / "rig.toml").write_text(MOCAP_RIG_TOML)
    (d / "map.toml").write_text(MOCAP_MAP_TOML)
    pd.DataFrame({"Time (ms)": np.arange(30) * 100, "Yaw (deg)": np.arange(30.0)}).to_csv(
        d / "raw.csv", index=False
    )
    (d / "gains.json").write_text(json.dumps({"loop": "attitude", "gains": {"kp": 1.0}}))
    (d / "camp.toml").write_text(
        'testbed = "tb.toml"\ncommand = "simulate"\nruns = 1\n[args]\nduration = 1\n'
    )
    os.symlink(d / "log.csv", d / "link.csv")
    os.link(d / "raw.csv", d / "hard.csv")
    return d


#: (args, the input the output names): every command, every output flag, = an input.
CASES = [
    (["simulate", "{tb.toml}", "-o", "{tb.toml}"], "tb.toml"),
    (["simulate", "{tb.toml}", "--json", "{tb.toml}"], "tb.toml"),
    (
        ["simulate", "cmg-yaw", "--scenario", "free", "--times", "{log.csv}", "-o", "{log.csv}"],
        "log.csv",
    ),  # fmt: skip
    (["balance", "{tb.toml}", "-o", "{tb.toml}"], "tb.toml"),
    (["balance", "{tb.toml}", "--json", "{tb.toml}"], "tb.toml"),
    (["balance", "{tb.toml}", "--log", "{tb.toml}"], "tb.toml"),  # the old spelling too
    (["gains", "{tb.toml}", "--json", "{tb.toml}"], "tb.toml"),
    (
        [
            "export",
            "cmg-yaw",
            "--loop",
            "attitude",
            "--gains",
            "{gains.json}",
            "--name",
            "gains",
            "-o",
            "{.}",
            "--force",
        ],
        "gains.json",
    ),  # fmt: skip
    (["simulate", "cmg-yaw", "--gains", "{gains.json}", "--json", "{gains.json}"], "gains.json"),
    (["report", "{tb.toml}", "-o", "{tb.toml}"], "tb.toml"),
    (
        ["report", "cmg-yaw", "--gains", "{gains.json}", "-o", "r.html", "--json", "{gains.json}"],
        "gains.json",
    ),  # fmt: skip
    (["report", "{tb.toml}", "--output", "{tb.toml}"], "tb.toml"),
    (["identify", "{tb.toml}", "{log.csv}", "--json", "{log.csv}"], "log.csv"),
    (["identify", "{tb.toml}", "{log.csv}", "--write-testbed", "{tb.toml}"], "tb.toml"),
    (["discrepancy", "{tb.toml}", "{log.csv}", "--json", "{log.csv}"], "log.csv"),
    (["discrepancy", "{tb.toml}", "{log.csv}", "--report", "{log.csv}"], "log.csv"),
    (["discrepancy", "{tb.toml}", "{log.csv}", "--write-testbed", "{tb.toml}"], "tb.toml"),
    (
        [
            "discrepancy",
            "{tb.toml}",
            "{log.csv}",
            "--validate",
            "{held.csv}",
            "--json",
            "{held.csv}",
        ],
        "held.csv",
    ),  # fmt: skip
    (["replay", "{tb.toml}", "{log.csv}", "--json", "{link.csv}"], "log.csv"),  # a symlink
    (["replay", "{tb.toml}", "{log.csv}", "--report", "{log.csv}"], "log.csv"),
    (["cmg", "envelope", "{tb.toml}", "-o", "{tb.toml}"], "tb.toml"),
    (["cmg", "envelope", "{tb.toml}", "-o", "e.png", "--data", "{tb.toml}"], "tb.toml"),
    (["campaign", "{camp.toml}", "-o", "{camp.toml}"], "camp.toml"),
    (["campaign", "{camp.toml}", "-o", "r.parquet", "--report", "{camp.toml}"], "camp.toml"),
    (["campaign", "{camp.toml}", "-o", "{tb.toml}"], "tb.toml"),  # the testbed it names
    (
        ["log", "import", "{rig.toml}", "{raw.csv}", "--map", "{map.toml}", "-o", "{raw.csv}"],
        "raw.csv",
    ),  # fmt: skip
    (["log", "import", "{raw.csv}", "--map", "{map.toml}", "-o", "{hard.csv}"], "raw.csv"),
    (
        ["log", "import", "{rig.toml}", "{raw.csv}", "--map", "{map.toml}", "-o", "{map.toml}"],
        "map.toml",
    ),  # fmt: skip
    (["log", "import", "{raw.csv}", "--map", "{map.toml}", "--output", "{raw.csv}"], "raw.csv"),
    (["log", "check", "{tb.toml}", "{log.csv}", "--json", "{log.csv}"], "log.csv"),
    (["log", "check", "{tb.toml}", "{log.csv}", "--json", "{tb.toml}"], "tb.toml"),
    (["log", "plot", "{tb.toml}", "{log.csv}", "-o", "{log.csv}"], "log.csv"),
    (["log", "plot", "{log.csv}", "--testbed", "{tb.toml}", "-o", "{tb.toml}"], "tb.toml"),
]
#: Commands that read no file of the user's (built-in names and numbers only).
NO_INPUT_FILES = {"cmg size", "demo", "testbed list", "testbed show", "testbed export"}


def _fill(args, d: Path) -> list[str]:
    return [re.sub(r"\{([^}]+)\}", lambda m: str(d / m.group(1)), a) for a in args]


def test_every_command_with_input_files_is_tried():
    tried = {" ".join(a[:2]) if a[0] in ("log", "cmg") else a[0] for a, _ in CASES}
    assert set(COMMANDS) - NO_INPUT_FILES <= tried


@pytest.mark.parametrize("args, victim", CASES, ids=[" ".join(a) for a, _ in CASES])
def test_an_output_that_is_an_input_is_refused(args, victim, files, capsys, monkeypatch):
    monkeypatch.chdir(files)
    before = {p.name: p.read_bytes() for p in files.iterdir() if p.is_file()}
    rc = run(_fill(args, files))
    err = [line for line in capsys.readouterr().err.splitlines() if "deprecated" not in line]
    assert rc == 2, err
    assert len(err) == 1 and "an input of this command" in err[0], err
    assert victim in err[0]
    after = {p.name: p.read_bytes() for p in files.iterdir() if p.is_file()}
    assert after == before  # every input byte-equal, nothing new written


def test_rewrite_old_spellings():
    args, notes = rewrite(["-q", "simulate", "tb", "--seed=3", "--output", "x.csv"])
    assert args == ["-q", "simulate", "tb", "--noise-seed=3", "--out", "x.csv"]
    assert len(notes) == 2 and all(n.startswith("deprecated: ") for n in notes)
    assert rewrite(["discrepancy", "tb", "l.csv", "--seed", "1"])[0][-2] == "--split-seed"
    assert rewrite(["balance", "tb", "--log", "x.csv"])[0] == ["balance", "tb", "--out", "x.csv"]
    args, _ = rewrite(["log", "check", "l.csv", "--json", "j.json", "--testbed", "tb.toml"])
    assert args == ["log", "check", "tb.toml", "l.csv", "--json", "j.json"]
    assert rewrite(["testbed", "list", "--json"])[0] == ["testbed", "list", "--json", "-"]
    assert rewrite(["testbed", "list", "--json", "x.json"]) == (
        ["testbed", "list", "--json", "x.json"],
        [],
    )
    assert rewrite(["simulate", "tb", "--noise-seed", "3"])[1] == []


def test_old_spellings_still_run_with_one_deprecation_line(tmp_path, capsys):
    out = tmp_path / "l.csv"
    rc = run(["simulate", "cmg-yaw", "--duration", "1", "--ideal", "--seed", "2",
              "--output", str(out)])  # fmt: skip
    err = capsys.readouterr().err.splitlines()
    assert rc == 0 and out.exists()
    assert len([e for e in err if "deprecated" in e]) == 2 and "--noise-seed" in "".join(err)


def test_testbed_list_json_path(tmp_path, capsys):
    path = tmp_path / "list.json"
    assert run(["testbed", "list", "--json", str(path)]) == 0
    names = [e["name"] for e in json.loads(path.read_text())]
    assert run(["testbed", "list", "--json"]) == 0  # the old switch: JSON on stdout
    captured = capsys.readouterr()
    assert [e["name"] for e in json.loads(captured.out.split("wrote")[-1].split("\n", 1)[1])] == (
        names
    )
    assert "deprecated" in captured.err


_PY_TYPES = re.compile(r"<[^>]*>|list\[|\b(?:int|float) range\b|\s(?:str|int|float|bool)\s")


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_shows_no_python_types(command, capsys):
    assert run([*command.split(), "--help"]) == 0
    text = capsys.readouterr().out
    usage_and_options = text[text.index("Usage:") :]
    assert not _PY_TYPES.search(usage_and_options), _PY_TYPES.search(usage_and_options)


def test_cmg_size_runs_with_its_defaults_table5(capsys):
    assert run(["cmg", "size"]) == 0
    text = capsys.readouterr().out
    # seed 001 Table 5: N_req 1.728 mN m, h0 0.8661 mN m s (4 significant digits)
    assert "1.728" in text and "0.8661" in text
    assert run(["cmg", "size", "--help"]) == 0
    help_text = capsys.readouterr().out
    assert "[default: 30.0]" in help_text and "[required]" not in help_text


def test_choices_not_text_in_help(capsys):
    for command, option, choices in (
        (["identify"], "--friction", "none|viscous|coulomb"),
        (["campaign"], "--study", "detection"),
    ):
        assert run([*command, "--help"]) == 0
        assert f"{option} {choices}" in capsys.readouterr().out


def _yaw_log(path: Path, n: int = 800, bad=range(500, 520), value=1e300) -> Path:
    rng = np.random.default_rng(1)
    t = np.arange(n) * 0.1  # the rig's 10 Hz
    yaw = 0.3 + 0.5 * t + 1e-3 * rng.normal(size=n)
    yaw[list(bad)] = value
    pd.DataFrame({"t": t, "yaw": yaw}).to_csv(path, index=False)
    return path


def test_log_check_names_exactly_the_overflow_rows_and_discrepancy_refuses(tmp_path, capsys):
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    log = _yaw_log(tmp_path / "log.csv")
    js = tmp_path / "check.json"
    # no tool can use the log: exit 2, the rows and every tool's "no" printed, nothing written
    assert run(["log", "check", str(tb), str(log), "--json", str(js)]) == 2
    captured = capsys.readouterr()
    text = captured.out
    assert "500-519" in text and "498" not in text and "521" not in text
    assert "no tool can use this log" in captured.err and "500-519" in captured.err
    assert not js.exists()
    assert run(["discrepancy", str(tb), str(log)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "row 500" in err[0] and "500-519" in err[0], err


@pytest.mark.parametrize("column", ["t", "yaw"])
@pytest.mark.parametrize("value", [float("inf"), float("nan"), -1e200, 2e100])
def test_same_rule_on_every_channel(tmp_path, capsys, column, value):
    from airbearing.io.log import BadCellsError, read_log

    path = tmp_path / "log.csv"
    t = np.arange(100) * 0.1
    df = pd.DataFrame({"t": t, "yaw": 0.1 * t})
    df.loc[[40, 41], column] = value
    df.to_csv(path, index=False)
    with pytest.raises(BadCellsError) as e:
        read_log(path)
    assert e.value.bad == {column: [40, 41]}


def test_values_at_the_limit_are_kept(tmp_path):
    from airbearing.io.log import OVERFLOW_LIMIT, read_log

    path = tmp_path / "log.csv"
    pd.DataFrame({"t": [0.0, 0.1, 0.2], "wz": [0.0, OVERFLOW_LIMIT, -OVERFLOW_LIMIT]}).to_csv(
        path, index=False
    )
    assert read_log(path).n == 3


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_shown_default_is_accepted_by_its_option(command):
    """A default in --help converts with the option's own type and lies in its range."""
    import typer.main

    cmd = COMMANDS[command]
    ctx = typer.main.get_command(app).make_context("airbearing", ["--help"], resilient_parsing=True)
    for param in cmd.params:
        default = param.default
        if default is None or callable(default) or param.name == "help":
            continue
        # the option's own conversion (type, choices, range) raises on a refused value
        value = param.get_runtime_param().coerce(default, param=param, ctx=ctx)
        lo, hi = getattr(param, "min", None), getattr(param, "max", None)
        for v in value if isinstance(value, tuple | list) else [value]:
            assert lo is None or v >= lo, (command, param.name)
            assert hi is None or v <= hi, (command, param.name)


def test_log_check_says_no_for_time_going_back(tmp_path, capsys):
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    t = np.arange(200) * 0.1
    t[50] = t[48]  # a logger hiccup: row 50 repeats an earlier time
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": t, "yaw": 0.2 * t}).to_csv(path, index=False)
    js = tmp_path / "c.json"
    assert run(["log", "check", str(tb), str(path), "--json", str(js)]) == 2
    assert not js.exists()  # exit 2 writes nothing
    captured = capsys.readouterr()
    assert "bad rows  50" in captured.out and "row 50" in captured.err
    assert run(["identify", str(tb), str(path)]) == 2


def test_log_commands_say_the_testbed_comes_first(tmp_path, capsys):
    log = _yaw_log(tmp_path / "log.csv", bad=[])
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    assert run(["log", "check", str(log), str(tb)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "the testbed comes first" in err
    assert run(["log", "check", str(tb), str(log)]) == 0
    assert run(["log", "check", str(log), "--testbed", str(tb)]) == 0  # the old spelling
    assert "deprecated" in capsys.readouterr().err
