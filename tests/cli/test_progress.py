"""Progress of long work: plain lines on stderr when it is not a terminal, --quiet silences.

Under pytest's capture stderr is not a terminal, so the in-process runs here see what a
pipe, a log file or CI sees.
"""

from __future__ import annotations

import io
import sys
import time

import pytest
from cli_run import run

from airbearing.cli import show_progress
from airbearing.progress import call, silent


@pytest.fixture(autouse=True)
def _loud():
    show_progress.set_quiet(False)
    yield
    show_progress.set_quiet(False)


def test_plain_lines_say_what_and_how_far(monkeypatch):
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    with show_progress.progress_display("demo") as progress:
        progress("section 1 of 2: CMG slews", 0, 2)
        progress("section 1 of 2: CMG slews", 0, 2)  # same step within a second: not repeated
        progress("section 2 of 2: balancing", 1, 2)
    lines = buf.getvalue().splitlines()
    assert lines[0] == "demo: section 1 of 2: CMG slews [0/2]"
    # steps that took no time predict nothing: no "about 0 s left" (time-left tests:
    # tests/cli/test_cli_output.py, tests/cli/test_cli_help_and_defaults.py)
    assert lines[1].startswith("demo: section 2 of 2: balancing [1/2")
    assert len(lines) == 2


def test_work_refused_at_once_prints_no_progress(monkeypatch, capfd):
    """A command that fails before PLAIN_DELAY prints its one error line and nothing else."""
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.5)
    with pytest.raises(ValueError), show_progress.progress_display("gains") as progress:
        progress("tuning the balancing loop")
        raise ValueError("bad input")
    time.sleep(0.7)  # the held-back line would have been printed by now
    assert capfd.readouterr().err == ""
    # work that lasts past the delay shows its line
    with show_progress.progress_display("gains") as progress:
        progress("tuning the balancing loop")
        time.sleep(0.8)
    assert capfd.readouterr().err == "gains: tuning the balancing loop\n"


def test_quiet_silences(monkeypatch):
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    show_progress.set_quiet(True)
    with show_progress.progress_display("demo") as progress:
        progress("anything", 1, 2)
    assert buf.getvalue() == ""


def test_library_progress_default_is_silent():
    assert call(None) is silent
    marker = []
    assert call(lambda *a: marker.append(a)) is not silent


@pytest.mark.parametrize(
    "args, label",
    [
        # the nominal inertia only (one corner of the box, not three): the same progress
        (["gains", "cmg-yaw", "--inertia-uncertainty", "0"], "gains:"),
        (["report", "cmg-yaw", "-o", "{tmp}/r.html"], "report:"),
    ],
    ids=["gains", "report"],
)
@pytest.mark.slow
def test_long_commands_show_progress_unless_quiet(args, label, tmp_path, capfd, monkeypatch):
    """Progress lines on a pipe. Their silence under ``--quiet`` is checked, with no delay
    either, on the quiet runs tests/cli/test_cli_help_and_defaults.py makes anyway (gains:
    test_an_unmet_specification_is_one_line; report: 25 s of work on one core,
    test_report_prints_its_margins_then_what_it_wrote): a second run here only repeated
    them."""
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)  # on a fast machine, too
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert run(args) == 0
    err = capfd.readouterr().err
    assert any(line.startswith(label) for line in err.splitlines()), err


# The demo's progress lines: tests/reporting/test_demo.py (the suite's one demo run).


@pytest.mark.slow
def test_balance_compare_shows_progress(tmp_path, capfd, monkeypatch):
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)  # short runs: show them anyway
    args = ["balance", "seed000-tabletop", "--compare", "mechanical,mixed", "--seeds", "1",
            "--duration", "20"]  # fmt: skip
    assert run(args) == 0
    assert any(ln.startswith("balance:") for ln in capfd.readouterr().err.splitlines())
