"""The bench's third round on the command line: progress that does not lie, defaults that
follow the testbed, defaults typed as shown, the grammar everywhere, messages and tables."""

from __future__ import annotations

import io
import json
import re
import sys

import pytest
from cli_run import run

from airbearing.cli import show_progress
from airbearing.progress import TimeLeft


@pytest.fixture(autouse=True)
def _loud():
    show_progress.set_quiet(False)
    yield
    show_progress.set_quiet(False)


# --- progress -------------------------------------------------------------------------


def test_time_left_says_nothing_once_run_out():
    # two 1 s steps, then a third that takes 158 s (identify's output-error fit)
    left = TimeLeft(0.0)
    assert left.update(1, 3, 1.0)[0] == pytest.approx(2.0)
    assert left.update(2, 3, 2.0)[0] == pytest.approx(1.0)
    assert left.update(2, 3, 2.4)[0] == pytest.approx(0.6)  # counts down with the clock
    for now in (3.0, 10.0, 160.0):  # the step runs on: no "about 0 s left"
        assert left.update(2, 3, now) is None


def test_no_estimate_from_a_step_that_took_no_time():
    # report: a 0.1 s first step of three said "about 0 s left" while the next took seconds
    left = TimeLeft(0.0)
    assert left.update(1, 3, 0.1) is None
    assert left.update(2, 3, 4.0)[0] == pytest.approx(2.0)


def test_a_fresh_estimate_after_one_ran_out_is_not_capped_by_it():
    left = TimeLeft(0.0)
    left.update(1, 4, 1.0)  # 3 s left
    assert left.update(1, 4, 30.0) is None  # ran out
    shown, _ = left.update(2, 4, 40.0)  # steps average 20 s: 40 s left
    assert shown == pytest.approx(40.0)


def _plain_lines(monkeypatch, calls) -> list[str]:
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    clock = {"t": 0.0}
    monkeypatch.setattr(show_progress.time, "monotonic", lambda: clock["t"])
    with show_progress.progress_display("identify") as progress:
        for t, what, done, total in calls:
            clock["t"] = t
            progress(what, done, total)
    return buf.getvalue().splitlines()


def test_plain_progress_shows_elapsed_time_instead_of_a_false_estimate(monkeypatch):
    fit = "fitting the output error"
    lines = _plain_lines(
        monkeypatch,
        [
            (0.0, "a", 0, 3),
            (1.0, "b", 1, 3),
            (2.0, fit, 2, 3),
            (60.0, fit, 2, 3),
            (160.0, fit, 2, 3),
        ],  # fmt: skip
    )
    assert lines[1] == "identify: b [1/3, about 2 s left]"
    assert lines[-2] == f"identify: {fit} [2/3, 1 min 0 s so far]"
    assert lines[-1] == f"identify: {fit} [2/3, 2 min 40 s so far]"
    assert not any("about 0 s" in line for line in lines)


def test_plain_progress_always_prints_the_last_step(monkeypatch):
    what = "runs done, 0 failed"
    calls = [(0.0, what, 0, 30)] + [(0.01 * k, what, k, 30) for k in range(1, 31)]
    lines = _plain_lines(monkeypatch, calls)
    assert lines[0] == f"identify: {what} [0/30]"
    assert lines[-1] == f"identify: {what} [30/30, done in 0 s]"
    assert len(lines) == 2  # throttled in between, the last one not


# --- defaults that follow the testbed; defaults typed as shown ---------------------------


def test_balance_method_follows_the_testbed(tmp_path):
    # seed 004's platform has no magnetorquers and no cage field: mechanical, not mixed
    out = tmp_path / "b.json"
    assert run(["balance", "seed004-platform", "--duration", "5", "--json", str(out)]) == 0
    assert json.loads(out.read_text())["method"] == "mechanical"


#: Options whose default the help shows, typed in a mode that does not use them: the
#: help says which mode they belong to, and typed in another one they are refused (they
#: ask for something the run would not do: the two-step sets its own runs, not 300 s).
_DEFAULT_IN_ANOTHER_MODE = [
    (["balance", "seed004-platform", "--two-step", "--duration", "300"], "--duration",
     "not with --two-step"),
    (["balance", "seed004-platform", "--two-step", "--seeds", "4"], "--seeds",
     "only with --compare"),
    (["balance", "seed004-platform", "--two-step", "--start", "auto"], "--start",
     "not with --two-step"),
    (["balance", "seed000-tabletop", "--compare", "mixed", "--noise-seed", "0"], "--noise-seed",
     "not with --compare"),
    (["identify", "cmg-yaw", "{log}", "--form", "integrated"], "--form",
     "Platform (dof 3) with --method equation-error"),
]  # fmt: skip


@pytest.mark.parametrize("args, option, says", _DEFAULT_IN_ANOTHER_MODE)
def test_a_default_typed_in_another_mode_is_refused_as_its_help_says(
    args, option, says, tmp_path, capsys
):
    help_text = _option_help(_help([args[0]], capsys), option).replace("- ", "-")
    assert says in help_text, help_text
    log = tmp_path / "slew.csv"
    if "{log}" in args:
        assert run(["-q", "simulate", "cmg-yaw", "--duration", "5", "-o", str(log)]) == 0
    capsys.readouterr()
    assert run([a.replace("{log}", str(log)) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"airbearing: error: {option}: "), err


# --- the grammar everywhere; options named as typed --------------------------------------


@pytest.mark.parametrize(
    "args",
    [
        ["balance", "seed000-tabletop", "--duration", "1", "--output", "{tmp}/b.csv"],
        ["demo", "--quick", "--output", "{tmp}/d.txt", "--help"],
    ],  # fmt: skip
    ids=["balance", "demo"],
)
def test_old_output_spelling_works_everywhere_cli_md_says(args, tmp_path, capsys):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert run(args) == 0
    assert f"'{args[0]} --output' is now '--out'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args, typed",
    [
        (["balance", "seed000-tabletop", "--log", "dep.txt"], "--log dep.txt"),
        (["cmg", "envelope", "cmg-yaw", "--output", "x"], "--output x"),
        (["cmg", "envelope", "cmg-yaw", "--out", "x"], "--out x"),
        (["cmg", "envelope", "cmg-yaw", "-o", "x"], "-o x"),
    ],  # fmt: skip
)
def test_output_errors_name_the_option_as_typed(args, typed, capsys):
    assert run(args) == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert err.startswith(f"airbearing: error: {typed}: expected a file ending in"), err


def test_global_switches_after_the_command(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    log = tmp_path / "s.csv"
    assert run(["simulate", "cmg-yaw", "--duration", "5", "-o", str(log), "-q"]) == 0
    err = capsys.readouterr().err
    assert not any(line.startswith("simulate:") for line in err.splitlines()), err
    assert run(["log", "check", "cmg-yaw", str(log), "--quiet"]) == 0


@pytest.mark.parametrize("words", [[], ["simulate"], ["cmg"], ["cmg", "size"], ["log", "check"]])
def test_dash_h_is_help_everywhere(words, capsys):
    assert run([*words, "-h"]) == 0
    assert capsys.readouterr().out.startswith("Usage: airbearing")


def test_usage_errors_name_the_program_once(capsys):
    assert run(["simulate"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "airbearing: error: simulate: Missing argument 'TESTBED'."
    assert run(["cmg", "envelope"]) == 2
    assert capsys.readouterr().err.startswith("airbearing: error: cmg envelope: Missing")


def test_campaign_options_named_with_values_as_typed(tmp_path, capsys):
    c = tmp_path / "c.toml"
    c.write_text('testbed = "cmg-yaw"\ncommand = "simulate"\nruns = 2\n[args]\nduration = 2\n')
    out = str(tmp_path / "r.parquet")
    assert run(["campaign", str(c), "-o", out, "--run-timeout", "0"]) == 2
    assert "error: --run-timeout 0: expected a time > 0 in s" in capsys.readouterr().err
    assert run(["campaign", str(c), "-o", out, "--scheduler", "bogus"]) == 2
    err = capsys.readouterr().err
    assert "error: --scheduler bogus: expected a Dask scheduler address" in err
    assert "tried" not in err


# --- small wordings ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "args, expected",
    [
        (["identify", "cmg-yaw", "{d}"], "{d}: is a directory, expected a log file"),
        (["log", "check", "cmg-yaw", "{d}"], "{d}: is a directory, expected a log file"),
    ],  # fmt: skip
)
def test_a_directory_given_as_a_log(args, expected, tmp_path, capsys):
    d = str(tmp_path)
    assert run([a.replace("{d}", d) for a in args]) == 2
    assert capsys.readouterr().err.strip() == "airbearing: error: " + expected.replace("{d}", d)


def test_an_output_that_is_the_log_says_the_log(tmp_path, capsys):
    log = tmp_path / "in.csv"
    assert run(["simulate", "cmg-yaw", "--duration", "5", "-o", str(log)]) == 0
    capsys.readouterr()
    assert run(["identify", "cmg-yaw", str(log), "--write-testbed", str(log)]) == 2
    assert f"is the log {log}, an input" in capsys.readouterr().err


def test_an_angle_unit_with_its_article(tmp_path, capsys):
    raw = tmp_path / "raw.csv"
    raw.write_text("time,yaw\n0,0\n0.1,0\n")
    m = tmp_path / "map.toml"
    m.write_text('[columns]\nt = "time"\nyaw = "yaw"\n[units]\nyaw = "furlong"\n')
    assert (
        run(["log", "import", "cmg-yaw", str(raw), "--map", str(m), "-o", str(tmp_path / "o.csv")])
        == 2
    )
    err = capsys.readouterr().err
    assert "expected an angle unit" in err, err


def test_report_with_gains_of_another_loop_says_to_pass_loop(tmp_path, capsys):
    g = tmp_path / "g.json"
    g.write_text(json.dumps({"loop": "balancing", "gains": {"kp": 0.1}}))
    assert run(["report", "cmg-yaw", "--gains", str(g), "-o", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err
    assert "gains of the balancing loop" in err and "pass --loop balancing" in err, err


# --- output shape ------------------------------------------------------------------------


@pytest.mark.slow
def test_report_prints_its_margins_then_what_it_wrote(tmp_path, capsys, monkeypatch):
    from airbearing.cli import show_progress

    # -q silences the progress lines even with no delay (their loud run:
    # tests/cli/test_progress.py)
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    html, js = tmp_path / "r.html", tmp_path / "r.json"
    assert run(["-q", "report", "cmg-yaw", "-o", str(html), "--json", str(js)]) == 0
    captured = capsys.readouterr()
    assert not any(line.startswith("report:") for line in captured.err.splitlines()), captured.err
    lines = captured.out.splitlines()
    assert lines[0].split() == ["check", "value", "required", "verdict"]
    assert any(line.startswith("phase margin (deg)") for line in lines)
    met = json.loads(js.read_text())["met"]
    assert f"specification met: {'yes' if met else 'no'}" in lines or not met
    assert lines[-2:] == [f"wrote {html}", f"wrote {js}"]


@pytest.mark.slow
def test_an_unmet_specification_is_one_line(capsys, monkeypatch):
    from airbearing.cli import show_progress

    # -q silences the progress lines even with no delay (the loud gains run:
    # tests/cli/test_progress.py)
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    # the nominal inertia only: one corner of the box, not three, for the same verdict
    assert run(["-q", "gains", "cmg-yaw", "--max-sensitivity", "1.01", "--bandwidth-hz", "5",
                "--inertia-uncertainty", "0"]) == 0  # fmt: skip
    captured = capsys.readouterr()
    assert not any(line.startswith("gains:") for line in captured.err.splitlines()), captured.err
    lines = captured.out.splitlines()
    verdicts = [line for line in lines if line.startswith("specification")]
    assert len(verdicts) == 1 and verdicts[0].startswith("specification NOT met: "), verdicts
    assert "bandwidth (Hz)" in verdicts[0] and "short by" in verdicts[0]


# --- help texts --------------------------------------------------------------------------


def _help(words, capsys) -> str:
    assert run([*words, "--help"]) == 0
    return capsys.readouterr().out


def _option_help(text: str, option: str) -> str:
    """The help of ``option`` (its lines up to the next option), on one line."""
    block: list[str] = []
    for line in text.splitlines():
        starts = line.startswith("  -")
        if block and starts:
            break
        if block or starts and option in line.split("  ")[1].replace(",", " ").split():
            block.append(line)
    return " ".join(" ".join(block).split())


@pytest.mark.parametrize(
    "words, option",
    [
        (["identify"], "--friction"),
        (["identify"], "--hold"),
        (["identify"], "--known-mass"),
        (["identify"], "--known-offset-xy"),
        (["discrepancy"], "--only"),
        (["gains"], "--offset-range-mm"),
        (["campaign"], "--run-timeout"),
    ],  # fmt: skip
)
def test_help_states_the_default_of_options_without_one_shown(words, option, capsys):
    assert "default" in _option_help(_help(words, capsys), option)


@pytest.mark.parametrize("words", [["simulate"], ["balance"], ["discrepancy"], ["cmg", "envelope"]])
def test_help_says_a_range_once(words, capsys):
    text = " ".join(_help(words, capsys).split())
    assert "x>=" not in text and "<=x" not in text and "; x" not in text


def test_help_details(capsys):
    assert "--compare" in _option_help(_help(["balance"], capsys), "--sweep")
    assert "[required]" in _option_help(_help(["report"], capsys), "--out")
    identify = _help(["identify"], capsys)
    assert "default" not in _option_help(identify, "--method").split("[default")[0]


@pytest.mark.parametrize("words", [[], ["cmg"], ["log"], ["testbed"]])
def test_command_lists_are_not_cut_mid_phrase(words, capsys):
    assert run([*words, "--help"]) == 0
    listing = capsys.readouterr().out.split("Commands:")[1]
    assert "..." not in listing and "eqs.\n" not in listing, listing


# --- tables ------------------------------------------------------------------------------


def _scalar_rows(out: str) -> dict[str, str]:
    rows = {}
    for line in out.splitlines():
        parts = [p for p in line.split("  ") if p.strip()]
        if len(parts) >= 2:
            rows[parts[0].strip()] = parts[1].strip()
    return rows


def test_balance_table_of_a_loop_that_is_not_stable(tmp_path, capsys):
    js = tmp_path / "u.json"
    args = ["-q", "balance", "seed000-tabletop", "--vertical-offset", "1e-4", "--duration", "5",
            "--json", str(js)]  # fmt: skip
    assert run(args) == 0
    out = capsys.readouterr().out
    data = json.loads(js.read_text())
    assert data["integral_time_constant_s"] is None  # the loop is not stable
    rows = _scalar_rows(out)
    assert rows["integral time constant"].startswith("none")
    assert rows["settling time"] == "does not settle"
    note = next(line for line in out.splitlines() if line.startswith("note:"))
    assert re.search(r"\d\.\d{5,}", note) is None, note  # 4 significant digits


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_two_step_table_in_words(capsys, monkeypatch, seed004_two_step):
    # the command gets the run of the library's defaults the balancing tests make anyway
    # (tests/conftest.py); its end-to-end run: tests/cli/test_cli_commands.py
    from airbearing.analysis.balancing import two_step as module

    def same_run(tb, *, seed=0, **options):  # the library's defaults, as the command passes
        assert tb.name == "seed004-platform" and set(options) == {"progress"}, options
        return seed004_two_step(seed)

    monkeypatch.setattr(module, "two_step", same_run)
    assert run(["-q", "balance", "seed004-platform", "--two-step"]) == 0
    out = capsys.readouterr().out
    for raw in ("ke rates", "in plane known", "ke std", "sliders step1", "identify method"):
        assert raw not in out, raw
    rows = _scalar_rows(out)
    assert rows["E from"] == "true rates (simulation)"
    assert rows["in-plane offset of step 1 used"] == "yes"


def test_long_numbers_in_sentences_are_tidied():
    from airbearing.cli.tables import tidy_numbers

    text = "offset [-3.690476190476191e-05, 0.0001, 45.1] m in run_1.csv, seed 004 eq. 47"
    assert tidy_numbers(text) == "offset [-3.69e-05, 0.0001, 45.1] m in run_1.csv, seed 004 eq. 47"


# --- testbed show/export take a file, as every command does --------------------------------


def test_testbed_show_and_export_take_a_file(tmp_path, capsys):
    first, second = tmp_path / "mine.toml", tmp_path / "copy.toml"
    assert run(["testbed", "export", "cmg-yaw", "-o", str(first)]) == 0
    capsys.readouterr()
    assert run(["testbed", "show", str(first)]) == 0
    assert capsys.readouterr().out == first.read_text()
    assert run(["testbed", "export", str(first), "-o", str(second)]) == 0
    text = second.read_text()
    assert text.count("# Exported from") == 1 and f"'{first}'" in text.splitlines()[0]
    assert run(["testbed", "export", str(first), "-o", str(first), "--force"]) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("x = 1\n")
    capsys.readouterr()
    assert run(["testbed", "show", str(bad)]) == 2
    assert "unknown key 'x'" in capsys.readouterr().err


def test_identify_hint_names_the_flags(tmp_path, capsys):
    log = tmp_path / "free.csv"
    assert run(["-q", "simulate", "seed004-platform", "--duration", "10", "-o", str(log)]) == 0
    # one free oscillation fixes inertia and offset only up to a scale: the answer (exit 0)
    # has no values and names the choices that fix it, as the command's flags
    assert run(["identify", "seed004-platform", str(log), "--method", "equation-error"]) == 0
    got = capsys.readouterr()
    said = got.out + got.err
    assert "--hold inertia" in said and "--known-offset-xy" in said, said
    assert "hold='" not in said and "known_offset_xy" not in said


@pytest.mark.parametrize("flag", ["-o", "--out", "--output"])
def test_demo_names_its_folder_option_as_typed(flag, tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("")
    assert run(["demo", flag, str(afile)]) == 2
    assert f"error: {flag} {afile}: is a file, expected a folder" in capsys.readouterr().err


def test_identify_of_several_logs_prints_no_list_repr(tmp_path, capsys):
    logs = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for i, log in enumerate(logs):
        args = ["-q", "simulate", "cmg-yaw", "--duration", "5", "--noise-seed", str(i)]
        assert run([*args, "-o", str(log)]) == 0
    capsys.readouterr()
    assert run(["-q", "identify", "cmg-yaw", *map(str, logs)]) == 0
    out = capsys.readouterr().out
    assert "outlier rows: none" in out and "[]" not in out, out
