"""Bug-bash fixes of the command line: Ctrl-C, overwriting, options that do not apply."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest
from cli_run import run


def _sigint_at(marker: str, args: list[str], cwd) -> tuple[int, str]:
    """Run ``airbearing ARGS`` in a subprocess, send SIGINT as soon as a progress line on
    its stderr contains ``marker`` (a phase of the work, whatever the machine's speed)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "airbearing", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a shell's background job ignores SIGINT, and a child inherits that
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    seen = []
    for line in proc.stderr:  # the progress lines (stderr is a pipe: one line per update)
        seen.append(line)
        if marker in line:
            break
    assert proc.poll() is None, f"the command ended before the interrupt: {''.join(seen)}"
    proc.send_signal(signal.SIGINT)
    _out, err = proc.communicate(timeout=120)
    return proc.returncode, "".join(seen) + err


@pytest.fixture(scope="module")
def long_spin(tmp_path_factory):
    """A 240 s free oscillation of the seed-000 tabletop with a viscous friction: its
    search works for seconds on any machine (a 60 s log's for about 1 s with a warm
    compiled cache, before the first progress line, which waits for 1 s of work)."""
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io.log import write_log
    from airbearing.io.testbed import load_testbed, write_testbed

    folder = tmp_path_factory.mktemp("long-spin")
    tb = load_testbed("seed000-tabletop")
    run = free_oscillation(
        tb, initial_rate=(0.35, 0.12, -1.5),
        q0=(0.99503719, 0.0, 0.0, 0.09950372), sliders=(0.002, -0.003, 0.004),
        effects={"viscous_friction": 8e-6}, duration=240.0, seed=7, attitude_noise=1e-3,
    )  # fmt: skip
    write_testbed(tb, folder / "testbed.toml")
    write_log(run.log, folder / "log.csv")
    return folder


@pytest.mark.slow
@pytest.mark.parametrize(
    "marker", ["screened", "added viscous_friction"], ids=["first-round", "second-round"]
)
def test_ctrl_c_during_a_solve_writes_nothing_and_exits_130(tmp_path, long_spin, marker):
    # CasADi's IPOPT catches the KeyboardInterrupt of a solve and carries on; the run
    # must still stop before writing anything. Interrupted when the progress says the
    # first round's candidates are being fitted, and once the first effect is added (the
    # second round's fits): after fixed delays of 1.5 and 3.5 s, as before, a machine with
    # a warm cache could finish the command first
    args = [
        "discrepancy", str(long_spin / "testbed.toml"), str(long_spin / "log.csv"),
        "--json", "int.json", "--report", "int.html",
    ]  # fmt: skip
    rc, err = _sigint_at(marker, args, tmp_path)
    assert rc == 130, err
    assert err.strip().splitlines()[-1] == "airbearing: interrupted; nothing written"
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ------------------------------------------------------------ existing files are not replaced

EXISTS = "the file exists; give --force to replace it"

#: Commands with one output that exists already ({X} is that file); refused before any work.
EXISTING = [
    ["testbed", "export", "cmg-yaw", "-o", "{X}.toml"],
    ["simulate", "cmg-yaw", "--duration", "1", "-o", "{X}.csv"],
    ["simulate", "cmg-yaw", "--duration", "1", "--json", "{X}.json"],
    ["gains", "cmg-yaw", "--json", "{X}.json"],
    ["report", "cmg-yaw", "-o", "{X}.html"],
    ["balance", "seed004-platform", "--two-step", "--json", "{X}.json"],
    ["cmg", "size", "--json", "{X}.json"],
    ["discrepancy", "cmg-yaw", "{LOG}", "--report", "{X}.html"],
    ["discrepancy", "cmg-yaw", "{LOG}", "--write-testbed", "{X}.toml"],
    ["replay", "cmg-yaw", "{LOG}", "--json", "{X}.json"],
    ["identify", "seed004-platform", "{LOG}", "--json", "{X}.json"],
    ["log", "check", "cmg-yaw", "{LOG}", "--json", "{X}.json"],
    ["log", "plot", "{LOG}", "-o", "{X}.png"],
    ["testbed", "list", "--json", "{X}.json"],
]


@pytest.mark.parametrize("args", EXISTING, ids=[" ".join(a[:2]) + " " + a[-2] for a in EXISTING])
def test_an_existing_output_is_refused_without_force(tmp_path, capsys, args):
    log = tmp_path / "in.csv"
    log.write_text("t,wz\n0,0\n")
    target = next(a for a in args if "{X}" in a).replace("{X}", str(tmp_path / "lab"))
    Path(target).write_text("a lab's file\n")
    args = [a.replace("{X}", str(tmp_path / "lab")).replace("{LOG}", str(log)) for a in args]
    assert run(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    option = args[args.index(target) - 1]
    assert err == [
        f"airbearing: error: {option} {target}: the file exists; give --force to replace it"
    ]
    assert Path(target).read_text() == "a lab's file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv", Path(target).name]


def test_force_replaces_an_output_but_never_an_input(tmp_path, capsys):
    tb = tmp_path / "tb.toml"
    assert run(["testbed", "export", "cmg-yaw", "-o", str(tb)]) == 0
    tb.write_text(tb.read_text() + "# the lab's note\n")
    assert run(["testbed", "export", "cmg-yaw", "-o", str(tb)]) == 2
    assert tb.read_text().endswith("# the lab's note\n")
    assert run(["testbed", "export", "cmg-yaw", "-o", str(tb), "--force"]) == 0
    assert "# the lab's note" not in tb.read_text()
    capsys.readouterr()
    # an input is refused with --force too
    assert run(["gains", str(tb), "--json", str(tb), "--force"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "an input of this command" in err[0]


def test_demo_reuses_its_own_folder_but_not_another_report(tmp_path, capsys):
    from airbearing.cli.demo import _demo_report
    from airbearing.cli.outputs import Outputs

    d = tmp_path / "demo-out"
    d.mkdir()
    report = d / "report.html"
    report.write_text("<!DOCTYPE html><html><head><title>my report</title></head></html>")
    assert run(["demo", "--out", str(d), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"airbearing: error: --out {report}: the file exists; give --force to replace it"
    ]
    assert "my report" in report.read_text()
    # the demo's own report from an earlier run may be replaced (the README's first command)
    report.write_text(
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'/>"
        "<title>airbearing demo on the built-in testbeds</title></head></html>"
    )
    assert _demo_report(report)
    own = Outputs().plan(report, "--out", (".html",), create_folder=True, own=_demo_report)
    assert own == report


# ------------------------------------------------------------ options that do not apply

#: (arguments, the option named): refused before any work, exit 2, one line.
NOT_APPLYING = [
    (["balance", "seed004-platform", "--two-step", "--duration", "5"], "--duration"),
    (
        ["balance", "seed004-platform", "--two-step", "--initial-offset-mm", "1"],
        "--initial-offset-mm",
    ),
    (["balance", "seed004-platform", "--two-step", "--start", "level"], "--start"),
    # given explicitly at its default value: still not used
    (["balance", "seed004-platform", "--two-step", "--duration", "300"], "--duration"),
    (["balance", "seed000-tabletop", "--seeds", "3", "--duration", "10"], "--seeds"),
    (
        ["balance", "seed000-tabletop", "--compare", "mechanical,mixed", "--method", "lyapunov"],
        "--method",
    ),
    (
        ["simulate", "cmg-yaw", "--scenario", "slew", "--initial-rate", "1", "0", "0"],
        "--initial-rate",
    ),
    (["simulate", "cmg-yaw", "--scenario", "slew", "--spin-rate", "1"], "--spin-rate"),
    (["simulate", "cmg-yaw", "--sliders", "0", "0", "0"], "--sliders"),
    (["simulate", "cmg-yaw", "--initial-quaternion", "1", "0", "0", "0"], "--initial-quaternion"),
    (["simulate", "seed004-platform", "--scenario", "free", "--yaw-deg", "30"], "--yaw-deg"),
    (["simulate", "seed004-platform", "--scenario", "free", "--steering", "sr"], "--steering"),
    (["gains", "cmg-yaw", "--offset-range-mm", "1", "2"], "--offset-range-mm"),
    (["gains", "cmg-yaw", "--split", "mechanical"], "--split"),
    (["report", "cmg-yaw", "--split", "mechanical", "-o", "{tmp}/r.html"], "--split"),
    (["identify", "seed004-platform", "{log}", "--form", "acceleration"], "--form"),
    (
        ["identify", "cmg-yaw", "{log}", "--method", "equation-error", "--form", "integrated"],
        "--form",
    ),
]


@pytest.mark.parametrize(
    "args, option", NOT_APPLYING, ids=[" ".join(a[:1] + a[2:6]) for a, _ in NOT_APPLYING]
)
def test_an_option_that_does_not_apply_is_refused(tmp_path, capsys, args, option):
    log = tmp_path / "in.csv"
    log.write_text("t,wz\n0,0\n")
    args = [a.replace("{tmp}", str(tmp_path)).replace("{log}", str(log)) for a in args]
    assert run(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"airbearing: error: {option}: "), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv"]


def test_options_at_their_defaults_are_not_refused(tmp_path):
    # the slew's defaults include --initial-rate 0 0 0 and --spin-rate 2: not given, not refused
    out = tmp_path / "s.json"
    assert (
        run(["--quiet", "simulate", "cmg-yaw", "--duration", "0.5", "--ideal", "--json", str(out)])
        == 0
    )
    assert out.exists()


# ------------------------------------------------------------ values checked


@pytest.mark.parametrize(
    "q, ok",
    [
        (("2", "0", "0", "0"), False),
        (("0", "0", "0", "0"), False),
        (("0.7071", "0.7071", "0", "0"), True),
    ],
)
def test_initial_quaternion_must_be_a_unit_quaternion(tmp_path, capsys, q, ok):
    # 0.7071 typed to 4 decimals: norm 0.99999 (within 1e-3); 2 0 0 0 is no rotation quaternion
    out = tmp_path / "f.json"
    args = ["--quiet", "simulate", "seed004-platform", "--scenario", "free", "--duration", "0.2",
            "--initial-quaternion", *q, "--json", str(out)]  # fmt: skip
    assert run(args) == (0 if ok else 2)
    err = capsys.readouterr().err.strip().splitlines()
    if not ok:
        assert err == [
            f"airbearing: error: --initial-quaternion {' '.join(q)}: expected a unit quaternion "
            f"qw qx qy qz (norm {2 if q[0] == '2' else 0}, 1 within 0.001)"
        ]
    assert out.exists() == ok


@pytest.mark.parametrize("name", ["viscous_friction", "coulomb_friction", "aero_drag"])
def test_a_negative_dissipative_effect_is_refused(tmp_path, capsys, name):
    # FORMATS.md: only inertia_error may be negative; negative friction feeds energy in
    from airbearing.io.vocabulary import EFFECTS

    unit = EFFECTS[name].unit
    assert (
        run(["simulate", "seed004-platform", "--scenario", "free", "--effect", f"{name}=-1e-3"])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"airbearing: error: --effect {name}=-1e-3: expected a value >= 0 {unit}, got -0.001"
    ]
    tb = tmp_path / "tb.toml"
    assert run(["testbed", "export", "seed004-platform", "-o", str(tb)]) == 0
    tb.write_text(tb.read_text() + f"\n[effects]\n{name} = [1e-6, -1e-6, 0]\n")
    capsys.readouterr()
    assert run(["simulate", str(tb), "--scenario", "free", "--json", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"effects.{name}" in err[0] and f">= 0 {unit}" in err[0], err
    assert not (tmp_path / "x.json").exists()


# ------------------------------------------------------------ messages name the flag

TWO_ROWS = (
    "t,yaw,wz,d1,d2,d3,d4,dd1,dd2,dd3,dd4,yaw_ref\n"
    "0,0,-0.00074,0,0,0,0,-1.1257,-1.1257,-1.1257,-1.1257,3.141592654\n"
    "0.05,0.0028,0.056,-0.056,-0.056,-0.056,-0.056,-1.1257,-1.1257,-1.1257,-1.1257,3.141592654\n"
)

#: (arguments, the one error line; "..." ends a prefix).
MESSAGES = [
    (["simulate", "cmg-yaw", "--noise-seed", "-1"], "--noise-seed -1: expected a value >= 0"),
    (["simulate", "cmg-yaw", "--noise-seed", "x"], "--noise-seed x: expected an integer"),
    (
        ["simulate", "cmg-yaw", "--scenario", "bad"],
        "--scenario bad: expected one of slew, free, spindown",
    ),
    (["cmg", "size", "--angle-deg=x"], "--angle-deg x: expected a number"),
    (
        ["balance", "seed000-tabletop", "--initial-offset-mm", "100"],
        "--initial-offset-mm 100: expected a finite number from -...",
    ),
    (
        ["simulate", "seed004-platform", "--scenario", "free", "--sliders", "1", "0", "0"],
        "--sliders 1 0 0: each must lie within...",
    ),
    (
        ["simulate", "cmg-yaw", "--scenario", "free", "--initial-rate", "1", "0", "0"],
        "--initial-rate 1 0 0: a dof = 1 bearing...",
    ),
    (
        ["identify", "seed004-platform", "{log}", "--known-mass", "-3"],
        "--known-mass -3: expected a finite number > 0 kg",
    ),
    (
        ["discrepancy", "cmg-yaw", "{log}", "--window", "0"],
        "--window 0: expected a finite number > 0 s",
    ),
    (["replay", "cmg-yaw", "{log}", "--window", "0"], "--window 0: expected a finite number > 0 s"),
    (["identify", "cmg-yaw", "{log}"], "{log}: 0 samples for 1 unknowns; give longer logs"),
]


@pytest.mark.parametrize("args, line", MESSAGES, ids=[" ".join(a[:4]) for a, _ in MESSAGES])
def test_a_bad_value_is_one_plain_line_naming_the_flag(tmp_path, capsys, args, line):
    log = tmp_path / "tworows.csv"
    log.write_text(TWO_ROWS)
    args = [a.replace("{log}", str(log)) for a in args]
    line = line.replace("{log}", str(log))
    assert run(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    if line.endswith("..."):
        assert err[0].startswith(f"airbearing: error: {line[:-3]}"), err
    else:
        assert err[0] == f"airbearing: error: {line}"


def test_progress_does_not_repeat_the_command(monkeypatch, capsys):
    from airbearing.cli import show_progress

    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    monkeypatch.setattr(show_progress, "QUIET", {"on": False})
    with show_progress.progress_display("replay") as progress:
        progress("replay: compiling and fitting the windows' initial states", 0, 1)
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["replay: compiling and fitting the windows' initial states [0/1]"]


def test_identify_says_what_it_wrote(tmp_path, example_case, capsys):
    case = example_case("identify_platform")
    out, tb = tmp_path / "id.json", tmp_path / "id.toml"
    args = [
        "--quiet",
        "identify",
        str(case / "testbed.toml"),
        # three slider positions fix the scale (one alone gives a scale-free answer, which
        # has no values to write)
        str(case / "log1.csv"),
        str(case / "log2.csv"),
        str(case / "log3.csv"),
        "--method",
        "equation-error",
        "--json",
        str(out),
        "--write-testbed",
        str(tb),
    ]
    assert run(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-2:] == [f"wrote {out}", f"wrote {tb}"]


# ------------------------------------------------------------ what a person reads


def test_json_to_stdout_is_for_testbed_list_only(tmp_path, capsys):
    assert run(["gains", "cmg-yaw", "--json", "-"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "airbearing: error: --json -: standard output is for 'testbed list --json -' only; "
        "give a file name"
    ]
    assert run(["testbed", "list", "--json", "-"]) == 0
    assert capsys.readouterr().out.lstrip().startswith("[")


def test_report_help_says_the_output_is_required(capsys):
    assert run(["report", "--help"]) == 0
    assert "[required]" in " ".join(capsys.readouterr().out.split())


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_gains_table_has_units(capsys, library_once):
    # the nominal inertia only (one corner, not three): the table is the same; the tuning
    # is the API tests' (tests/conftest.py library_once), what is tested is the table
    assert run(["--quiet", "gains", "cmg-yaw", "--inertia-uncertainty", "0"]) == 0
    lines = [line.split() for line in capsys.readouterr().out.splitlines()[:5] if line.strip()]
    rows = {line[0]: line[1:] for line in lines}
    assert rows["gain"] == ["value", "unit"]
    assert rows["K_p"][1] == "1/s" and rows["K_i"][1] == "1/s^2" and rows["K_w"][1] == "-"


def test_summary_ratios_and_dipole_have_their_unit_and_no_stray_row():
    from airbearing.cli.tables import human_summary

    text = human_summary(
        {"dipole_rms": 0.04, "ratios": {"of": "mixed/mechanical", "g_perp_rms": 1.05}}
    )
    lines = [line.split() for line in text.splitlines()]
    assert ["dipole", "rms", "0.04", "A", "m^2"] in lines
    assert "ratios (mixed/mechanical):" in text.splitlines()
    assert not any(line and line[0] == "of" for line in lines)


def test_a_toml_boolean_is_shown_as_toml_writes_it(tmp_path, capsys):
    tb = tmp_path / "tb.toml"
    assert run(["testbed", "export", "cmg-yaw", "-o", str(tb)]) == 0
    tb.write_text(tb.read_text().replace("\ndof = 1\n", "\ndof = true\n", 1))
    capsys.readouterr()
    assert run(["gains", str(tb)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("key 'body.dof': expected one of 1, 3, got true"), err


def test_log_check_tool_table_says_each_answer_once(example_case, capsys):
    case = example_case("platform_viscous")
    assert run(["--quiet", "log", "check", str(case / "testbed.toml"), str(case / "log.csv")]) == 0
    out = capsys.readouterr().out.splitlines()
    start = next(i for i, line in enumerate(out) if line.startswith("tool "))
    rows = [line for line in out[start + 2 :] if line.strip()]
    whys = [line.split(maxsplit=1)[1] for line in rows]
    assert len(set(whys)) == len(whys), rows
    names = " ".join(rows)
    for tool in ("simulate replay", "identify", "discrepancy", "replay", "balance"):
        assert tool in names
    assert not any(w.count("segment(s)") > 1 for w in whys), rows


def test_a_fit_pinned_at_zero_is_read_as_zero_not_refused():
    # an interior-point fit at its bound ends a roundoff below it (-7e-19 N m seen in a
    # discrepancy campaign); 1e-10 SI is 3 orders below any real rig's friction or drag
    from airbearing.errors import InputError
    from airbearing.io.vocabulary import ROUNDOFF, validate_effect_value

    assert validate_effect_value("coulomb_friction", -7e-19, "x") == 0.0
    assert validate_effect_value("aero_drag", [1e-6, -ROUNDOFF / 2, 0], "x") == (1e-6, 0.0, 0.0)
    with pytest.raises(InputError, match=">= 0 N m s, got -1e-09"):
        validate_effect_value("viscous_friction", -1e-9, "x")


def test_balance_note_names_the_flag(capsys):
    args = [
        "--quiet",
        "balance",
        "seed000-tabletop",
        "--vertical-offset",
        "1e-5",
        "--duration",
        "5",
    ]
    assert run(args) == 0
    note = [line for line in capsys.readouterr().out.splitlines() if line.startswith("note:")]
    assert note and "--vertical-offset" in note[0] and "vertical_offset" not in note[0]


@pytest.mark.slow
def test_defaults_that_depend_on_the_testbed_are_ones_it_accepts(tmp_path):
    import json

    # --scenario: slew needs a CMG, so a platform simulates a free oscillation
    assert run(["simulate", "seed004-platform", "--duration", "2", "--json",
                str(tmp_path / "s.json")]) == 0  # fmt: skip
    assert json.loads((tmp_path / "s.json").read_text())["scenario"] == "free"
    # --loop and --split: a platform without a cage field tunes the mechanical balancing PID
    # (one corner, the nominal inertia at the testbed's own vertical offset, not the nine of
    # the default box: --loop and --split do not depend on the box; the default box's
    # tuning is test_tuning.py's test_balancing_loop_of_seed004_meets_its_spec)
    assert run(["gains", "seed004-platform", "--inertia-uncertainty", "0",
                "--offset-range-mm", "-2.6", "-2.6",
                "--json", str(tmp_path / "g.json")]) == 0  # fmt: skip
    doc = json.loads((tmp_path / "g.json").read_text())
    assert doc["loop"] == "balancing" and doc["split"] == "mechanical"
