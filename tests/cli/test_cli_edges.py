"""The command line at the edges a lab hits in its first week (issue 14).

Every command, with an output it cannot write, an output folder that does not exist, a
mix of a good and a bad output, NaN/inf/negative/absurd numbers: exit status 2, one line
on stderr, no traceback, and no new file anywhere. Plus the one error path (internal
errors, --debug), the global options, the choices in --help, and the start-up imports.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from cli_run import run

from airbearing.cli import _register, app

_register()


def _registered() -> set[str]:
    import typer.main

    return set(typer.main.get_command(app).commands)


COMMANDS = _registered()

SIZE = ["cmg", "size", "--angle-deg", "30", "--time", "2", "--inertia", "0.0033"]
ENV = ["cmg", "envelope", "cmg-yaw", "-o", "{OK}/e.png"]

#: (command, args): each must be refused with exit 2, one line, nothing written.
#: {RO} a folder that cannot be written, {MISSING} a folder that does not exist, {FILE}
#: a regular file (used as a folder), {OK} a writable folder, {CMGLOG}/{PLATLOG} logs.
CASES = [
    ("simulate", ["simulate", "cmg-yaw", "-o", "{RO}/l.csv"]),
    ("simulate", ["simulate", "cmg-yaw", "--json", "{MISSING}/s.json"]),
    ("simulate", ["simulate", "cmg-yaw", "--json", "{FILE}/s.json"]),
    ("simulate", ["simulate", "cmg-yaw", "-o", "{OK}/l.csv", "--json", "{RO}/s.json"]),
    ("simulate", ["simulate", "cmg-yaw", "-o", "{OK}/l.txt"]),
    ("simulate", ["simulate", "cmg-yaw", "-o", "{OK}/same.csv", "--json", "{OK}/same.csv"]),
    ("simulate", ["simulate", "cmg-yaw", "--duration", "nan"]),
    ("simulate", ["simulate", "cmg-yaw", "--duration", "inf"]),
    ("simulate", ["simulate", "cmg-yaw", "--duration", "-5"]),
    ("simulate", ["simulate", "cmg-yaw", "--duration", "1e9"]),
    ("simulate", ["simulate", "cmg-yaw", "--yaw-deg", "1e9"]),
    ("simulate", ["simulate", "cmg-yaw", "--yaw-deg", "nan"]),
    ("simulate", ["simulate", "cmg-yaw", "--noise-seed", "-1"]),
    ("simulate", ["simulate", "cmg-yaw", "--axis", "0", "0", "0"]),
    ("simulate", ["simulate", "cmg-yaw", "--steering", "nope"]),
    ("simulate", ["simulate", "cmg-yaw", "--effect", "viscous_friction=inf"]),
    (
        "simulate",
        ["simulate", "seed000-tabletop", "--scenario", "free", "--initial-rate", "nan", "0", "0"],
    ),  # fmt: skip
    (
        "simulate",
        ["simulate", "seed000-tabletop", "--scenario", "free", "--attitude-noise", "-1"],
    ),  # fmt: skip
    ("balance", ["balance", "seed000-tabletop", "--json", "{RO}/b.json"]),
    ("balance", ["balance", "seed000-tabletop", "-o", "{OK}/a.csv", "--json", "{RO}/b.json"]),
    ("balance", ["balance", "seed000-tabletop", "--json", "{MISSING}/b.json"]),
    ("balance", ["balance", "seed000-tabletop", "--duration", "nan"]),
    ("balance", ["balance", "seed000-tabletop", "--duration", "-1"]),
    ("balance", ["balance", "seed000-tabletop", "--duration", "1e9"]),
    ("balance", ["balance", "seed000-tabletop", "--noise-seed", "-1"]),
    ("balance", ["balance", "seed000-tabletop", "--initial-offset-mm", "inf"]),
    ("balance", ["balance", "seed000-tabletop", "--method", "nope"]),
    ("export", ["export", "cmg-yaw", "--loop", "attitude", "-o", "{RO}/c"]),
    ("export", ["export", "cmg-yaw", "--loop", "attitude", "-o", "{FILE}"]),
    ("export", ["export", "cmg-yaw", "--loop", "balancing", "-o", "{OK}/c"]),
    ("export", ["export", "cmg-yaw", "--loop", "attitude", "--name", "1x", "-o", "{OK}/c"]),
    ("export", ["export", "cmg-yaw", "--loop", "attitude", "--check", "{PLATLOG}"]),
    ("export", ["export", "cmg-yaw", "--loop", "attitude"]),
    ("gains", ["gains", "cmg-yaw", "--json", "{RO}/g.json"]),
    ("gains", ["gains", "cmg-yaw", "--json", "{MISSING}/g.json"]),
    ("gains", ["gains", "cmg-yaw", "--phase-margin-deg", "nan"]),
    ("gains", ["gains", "cmg-yaw", "--bandwidth-hz", "-1"]),
    ("gains", ["gains", "cmg-yaw", "--inertia-uncertainty", "inf"]),
    ("gains", ["gains", "cmg-yaw", "--loop", "roll"]),
    ("report", ["report", "cmg-yaw", "-o", "{RO}/r.html"]),
    ("report", ["report", "cmg-yaw", "-o", "{OK}/r.html", "--json", "{RO}/m.json"]),
    ("report", ["report", "cmg-yaw", "-o", "{MISSING}/r.html"]),
    ("report", ["report", "cmg-yaw"]),
    ("identify", ["identify", "seed000-tabletop", "{PLATLOG}", "--json", "{RO}/i.json"]),
    (
        "identify",
        [
            "identify",
            "seed000-tabletop",
            "{PLATLOG}",
            "--json",
            "{OK}/i.json",
            "--write-testbed",
            "{RO}/t.toml",
        ],
    ),  # fmt: skip
    ("identify", ["identify", "seed000-tabletop", "{PLATLOG}", "--json", "{MISSING}/i.json"]),
    ("identify", ["identify", "seed000-tabletop", "{PLATLOG}", "--known-mass", "nan"]),
    ("identify", ["identify", "seed000-tabletop", "{PLATLOG}", "--known-mass", "-1"]),
    ("identify", ["identify", "seed000-tabletop", "{PLATLOG}", "--method", "nope"]),
    ("discrepancy", ["discrepancy", "cmg-yaw", "{CMGLOG}", "--json", "{RO}/d.json"]),
    (
        "discrepancy",
        ["discrepancy", "cmg-yaw", "{CMGLOG}", "--json", "{OK}/d.json", "--report", "{RO}/r.html"],
    ),  # fmt: skip
    ("discrepancy", ["discrepancy", "cmg-yaw", "{CMGLOG}", "--report", "{MISSING}/r.html"]),
    ("discrepancy", ["discrepancy", "cmg-yaw", "{CMGLOG}", "--max-effects", "-1"]),
    ("discrepancy", ["discrepancy", "cmg-yaw", "{CMGLOG}", "--window", "nan"]),
    ("discrepancy", ["discrepancy", "cmg-yaw", "{CMGLOG}", "--split-seed", "-1"]),
    ("cmg", [*SIZE, "--json", "{RO}/c.json"]),
    ("cmg", [*SIZE, "--json", "{MISSING}/c.json"]),
    ("cmg", ["cmg", "size", "--angle-deg", "30", "--time", "nan", "--inertia", "0.0033"]),
    ("cmg", ["cmg", "size", "--angle-deg", "30", "--time", "2", "--inertia", "-1"]),
    ("cmg", [*SIZE, "--flywheel-rpm", "inf"]),
    ("cmg", [*SIZE, "--inner-radius", "0.02"]),
    ("cmg", ["cmg", "envelope", "cmg-yaw", "-o", "{RO}/e.png"]),
    ("cmg", ["cmg", "envelope", "cmg-yaw", "-o", "{MISSING}/e.png"]),
    ("cmg", [*ENV, "--data", "{RO}/s.csv"]),
    ("cmg", [*ENV, "--resolution", "100000"]),
    ("cmg", [*ENV, "--skew-deg", "nan"]),
    ("cmg", ["cmg", "envelope", "seed000-tabletop", "-o", "{OK}/e.png"]),
    ("demo", ["demo", "--out", "{RO}/d"]),
    ("demo", ["demo", "--out", "{MISSING}/d"]),
    ("demo", ["demo", "--out", "{FILE}"]),
    ("testbed", ["testbed", "export", "cmg-yaw", "-o", "{RO}/t.toml"]),
    ("testbed", ["testbed", "export", "cmg-yaw", "-o", "{MISSING}/t.toml"]),
    ("testbed", ["testbed", "export", "cmg-yaw", "-o", "{OK}/t.json"]),
    ("testbed", ["testbed", "export", "nope", "-o", "{OK}/t.toml"]),
    ("testbed", ["testbed", "show", "nope"]),
    ("campaign", ["campaign", "{CAMPAIGN}", "-o", "{RO}/r.parquet"]),
    ("campaign", ["campaign", "{CAMPAIGN}", "-o", "{MISSING}/r.parquet"]),
    ("campaign", ["campaign", "{CAMPAIGN}", "-o", "{OK}/r.parquet", "--report", "{RO}/c.html"]),
    ("log", ["log", "check", "seed000-tabletop", "{PLATLOG}", "--json", "{RO}/c.json"]),
    ("log", ["log", "plot", "seed000-tabletop", "{PLATLOG}", "-o", "{RO}/p.png"]),
    ("log", ["log", "check", "seed000-tabletop", "{PLATLOG}", "--json", "{MISSING}/c.json"]),
    ("log", ["log", "check", "{PLATLOG}"]),
    ("log", ["log", "plot", "seed000-tabletop", "{PLATLOG}", "-o", "{OK}/p.txt"]),
    ("replay", ["replay", "cmg-yaw", "{CMGLOG}", "--json", "{RO}/r.json"]),
    (
        "replay",
        ["replay", "cmg-yaw", "{CMGLOG}", "--json", "{OK}/r.json", "--report", "{RO}/r.html"],
    ),  # fmt: skip
    ("replay", ["replay", "cmg-yaw", "{CMGLOG}", "--window", "nan"]),
    ("replay", ["replay", "cmg-yaw", "{CMGLOG}", "--window", "-1"]),
    ("campaign", ["campaign", "{CAMPAIGN}", "-o", "{OK}/r.parquet", "--workers", "-1"]),
]

#: A refusal for these reasons would mean the case itself is wrong (an option renamed).
_NOT_THE_POINT = ("No such option", "Missing argument", "Missing option", "unexpected extra")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Small logs made by the package's simulator (5 s)."""
    from airbearing.analysis.simulation.scenarios import free_oscillation, slew
    from airbearing.io.log import write_log
    from airbearing.io.testbed import load_testbed

    d = tmp_path_factory.mktemp("logs")
    write_log(slew(load_testbed("cmg-yaw"), duration=5.0, ideal=True).log, d / "cmg.csv")
    run_ = free_oscillation(load_testbed("seed000-tabletop"), initial_rate=(0.2, 0.1, -1.0),
                            duration=5.0)  # fmt: skip
    write_log(run_.log, d / "platform.csv")
    camp = d / "campaign.toml"
    camp.write_text(
        'testbed = "cmg-yaw"\ncommand = "simulate"\nruns = 2\nseed = 1\n'
        '[args]\nscenario = "slew"\nduration = 2\nideal = true\n'
    )
    return {"CMGLOG": d / "cmg.csv", "PLATLOG": d / "platform.csv", "CAMPAIGN": camp}


@pytest.fixture
def places(tmp_path, monkeypatch):
    """The folders of a case; a read-only folder stays read-only for root too."""
    ro, ok = tmp_path / "ro", tmp_path / "ok"
    ro.mkdir()
    ok.mkdir()
    (tmp_path / "afile").write_text("x")
    os.chmod(ro, 0o555)
    if os.geteuid() == 0:  # root writes anywhere: make the checks see what a user sees
        real = os.access

        def access(path, mode, *a, **kw):
            p = Path(path).resolve()
            if mode & os.W_OK and (p == ro.resolve() or ro.resolve() in p.parents):
                return False
            return real(path, mode, *a, **kw)

        monkeypatch.setattr(os, "access", access)
    yield {"RO": ro, "OK": ok, "MISSING": tmp_path / "missing", "FILE": tmp_path / "afile"}
    os.chmod(ro, 0o755)


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*")}


def _fill(args, places, logs):
    subs = {**{k: str(v) for k, v in places.items()}, **{k: str(v) for k, v in logs.items()}}
    out = []
    for a in args:
        for k, v in subs.items():
            a = a.replace("{" + k + "}", v)
        out.append(a)
    return out


@pytest.mark.parametrize(
    "command, args",
    [c for c in CASES if c[0] in COMMANDS],
    ids=[" ".join(c[1]).replace("{", "").replace("}", "") for c in CASES if c[0] in COMMANDS],
)
def test_refused_with_one_line_and_nothing_written(command, args, places, logs, tmp_path, capfd):
    before = _files(tmp_path)
    logs_before = _files(logs["CMGLOG"].parent)
    rc = run(_fill(args, places, logs))
    err = capfd.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("airbearing: error: "), err
    assert "Traceback" not in err and "np.float64" not in err
    assert not any(x in err for x in _NOT_THE_POINT), f"the case is out of date: {err}"
    assert _files(tmp_path) == before, "a file was written"
    assert _files(logs["CMGLOG"].parent) == logs_before


def test_every_command_is_walked():
    walked = {c for c, _ in CASES}
    assert COMMANDS <= walked | {"report"}, f"commands without edge cases: {COMMANDS - walked}"


def test_bare_airbearing_prints_help(capfd):
    assert run([]) == 0
    out, err = capfd.readouterr()
    assert "Usage: airbearing" in out and "simulate" in out
    assert "error" not in err


def test_version(capfd):
    from airbearing import __version__

    assert run(["--version"]) == 0
    assert capfd.readouterr().out.strip() == f"airbearing {__version__}"


def test_group_without_command_prints_its_help(capfd):
    assert run(["cmg"]) == 0
    assert "size" in capfd.readouterr().out


def test_internal_error_is_one_line_and_traceback_only_with_debug(monkeypatch, tmp_path, capfd):
    import airbearing.analysis.simulation.scenarios as scenarios

    def boom(*a, **kw):
        raise ZeroDivisionError("a bug\non two lines")

    monkeypatch.setattr(scenarios, "slew", boom)
    out = tmp_path / "s.json"
    assert run(["simulate", "cmg-yaw", "--json", str(out)]) == 1
    err = capfd.readouterr().err
    assert err.strip().splitlines() == [
        "airbearing: internal error: ZeroDivisionError: a bug on two lines "
        "(run with --debug for the traceback)"
    ]
    assert not out.exists()
    assert run(["--debug", "simulate", "cmg-yaw", "--json", str(out)]) == 1
    err = capfd.readouterr().err
    assert "Traceback" in err and "ZeroDivisionError" in err
    assert not out.exists()


def test_solver_failure_exits_1_with_one_line(monkeypatch, capfd):
    import airbearing.analysis.simulation.scenarios as scenarios
    from airbearing.errors import SolverError

    def fail(*a, **kw):
        raise SolverError("IPOPT: restoration failed")

    monkeypatch.setattr(scenarios, "slew", fail)
    assert run(["simulate", "cmg-yaw"]) == 1
    assert capfd.readouterr().err.strip() == "airbearing: failed: IPOPT: restoration failed"


#: Fixed-set options and the commands whose --help must list their choices.
CHOICES = [
    (["simulate"], "--steering", ["mp", "sr", "gsr", "sda"]),
    (["simulate"], "--scenario", ["slew", "free"]),
    (["simulate"], "--rate-limit", ["scale", "clip"]),
    (["gains"], "--loop", ["balancing", "attitude"]),
    (["gains"], "--split", ["mixed", "mechanical"]),
    (["report"], "--loop", ["balancing", "attitude"]),
    (["balance"], "--method", ["mechanical", "mixed", "lyapunov", "adaptive"]),
    (["balance"], "--start", ["rest", "level", "auto"]),
    (["identify"], "--method", ["output-error", "equation-error"]),
]


@pytest.mark.parametrize("cmd, option, values", CHOICES, ids=[f"{c[0][0]} {c[1]}" for c in CHOICES])
def test_help_lists_the_choices(cmd, option, values, capfd):
    assert run([*cmd, "--help"]) == 0
    out = " ".join(capfd.readouterr().out.split())
    assert option in out and all(v in out for v in values), out
    # the parser knows the set: a value outside it is refused, naming the valid ones
    positional = ["cmg-yaw", "missing.csv"] if cmd == ["identify"] else ["cmg-yaw"]
    assert run([*cmd, *positional, option, "nope"]) == 2
    err = capfd.readouterr().err
    assert all(v in err for v in values), err


def test_cli_choices_agree_with_the_library():
    from airbearing.cli import cmg, gains, simulate
    from airbearing.design import loops, sizing, steering

    assert set(simulate.STEERING) == set(steering.STEERING_LAWS)
    from airbearing.analysis.simulation.scenarios import SCENARIO_DURATIONS

    durations = ", ".join(f"{k} {v:g}" for k, v in SCENARIO_DURATIONS.items())
    assert simulate.DURATIONS_HELP == durations
    assert set(gains.LOOPS) == set(loops.LOOPS) and set(gains.SPLITS) == set(loops.SPLITS)
    t5 = sizing.TABLE5_DEFAULTS
    assert cmg.TABLE5["gimbal_rate_deg"] == pytest.approx(
        t5["gimbal_rate"] * 180 / 3.141592653589793
    )
    assert cmg.TABLE5["skew_deg"] == pytest.approx(t5["skew"] * 180 / 3.141592653589793)
    assert cmg.TABLE5["flywheel_rpm"] == pytest.approx(
        t5["flywheel_speed"] * 60 / 2 / 3.141592653589793
    )
    for k in ("inner_radius", "outer_radius", "density"):
        assert cmg.TABLE5[k] == t5[k]


HEAVY = ("casadi", "cvxpy", "control", "pandas", "matplotlib", "scipy")


def _culprits(importtime: str, heavy: list[str]) -> dict[str, str]:
    """Which ``airbearing.cli`` module imported each heavy module (``-X importtime`` tree).

    The tree lists a module's imports before the module itself, indented deeper; the
    first later line with a shallower ``airbearing.*`` name is the importer.
    """
    rows = []
    for line in importtime.splitlines():
        if line.startswith("import time:") and line.count("|") == 2:
            name = line.split("|")[2]
            rows.append((len(name) - len(name.lstrip()), name.strip()))
    found = {}
    for i, (depth, name) in enumerate(rows):
        if name in heavy and name not in found:
            chain = []
            for d, n in rows[i + 1 :]:
                if d < depth and n.startswith("airbearing"):
                    chain.append(n)
                    depth = d
                    if n.startswith("airbearing.cli."):
                        break
            found[name] = " <- ".join(chain) or "?"
    return found


def test_help_imports_no_numerical_library():
    """`airbearing --help` and `airbearing CMD --help` (every command) in a fresh process."""
    code = textwrap.dedent(
        f"""
        import sys, json
        from airbearing.cli import main, _register, app
        import typer.main
        def call(args):
            try:
                main(args)
            except SystemExit:
                pass
        call(["--help"])
        _register()
        group = typer.main.get_command(app)
        for name, cmd in group.commands.items():
            call([name, "--help"])
            for sub in list(getattr(cmd, "commands", {{}}) or []):
                call([name, sub, "--help"])
        print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))
        """
    )
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    heavy = json.loads(out.stdout.strip().splitlines()[-1])
    assert heavy == [], f"--help imports {heavy}: {_culprits(out.stderr, heavy)}"


def test_numbers_in_messages_are_plain():
    import numpy as np

    from airbearing.cli.common import check_log_size, number
    from airbearing.errors import InputError

    with pytest.raises(InputError) as e:
        number("--duration", np.float64(-5.0), lo=0, lo_open=True, unit="s")
    assert str(e.value) == "--duration -5: expected a finite number > 0 s"
    with pytest.raises(InputError, match=r"--duration 1e\+09 s: the log would have .* GiB|TiB"):
        check_log_size("--duration", 1e9, 20.0)
    check_log_size("--duration", 3600.0, 20.0)  # a 1 h log fits (72,000 rows)


def test_outputs_all_or_nothing(tmp_path):
    from airbearing.cli.outputs import Outputs
    from airbearing.errors import InputError

    keep = tmp_path / "keep.json"
    keep.write_text("old")
    out = Outputs(force=True)  # keep.json is replaced on success (--force)
    a = out.plan(tmp_path / "a.csv", "-o", (".csv",))
    k = out.plan(keep, "--json", (".json",))
    b = out.plan(tmp_path / "b.html", "--report", (".html",))
    out.text(a, "a")
    out.text(k, "new")

    def broken(tmp):
        raise OSError(28, "No space left on device")

    out.file(b, broken)
    with pytest.raises(InputError, match="--report .*b.html: cannot write it"):
        out.commit()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.json"]
    assert keep.read_text() == "old"


def test_outputs_plan_refuses_before_work(tmp_path):
    from airbearing.cli.outputs import Outputs
    from airbearing.errors import InputError

    out = Outputs()
    with pytest.raises(InputError, match="expected a file ending in .json"):
        out.plan(tmp_path / "x.txt", "--json", (".json",))
    with pytest.raises(InputError, match="does not exist"):
        out.plan(tmp_path / "no" / "x.json", "--json", (".json",))
    with pytest.raises(InputError, match="is a folder"):
        out.plan(tmp_path, "--json", ())
    if Path("/proc/self").is_dir():  # Linux: a folder no one can create files in, not even root
        with pytest.raises(InputError, match="cannot write in folder '/proc'"):
            out.plan("/proc/x.json", "--json", (".json",))
        with pytest.raises(InputError, match="cannot create it in folder '/proc'"):
            out.plan("/proc/d/report.html", "--out", (".html",), create_folder=True)
    # a folder to create: its parent must exist; commit creates it
    p = out.plan(tmp_path / "new" / "r.html", "--out", (".html",), create_folder=True)
    out.text(p, "<html></html>")
    out.commit()
    assert (tmp_path / "new" / "r.html").read_text() == "<html></html>"


@pytest.mark.parametrize(
    ("option", "value", "words"),
    [("--gap", "150", "expected START:LENGTH"), ("--glitch", "rate_drift:4", "KIND:ROW")],
)
def test_simulate_artefact_errors_name_the_flag(capfd, option, value, words):
    """The library's parsers name their parameter (gap, glitch); the CLI names its flag."""
    assert run(["simulate", "cmg-yaw", "--scenario", "free", option, value]) == 2
    err = capfd.readouterr().err
    assert f"{option} '{value}'" in err and words in err, err
