"""The bench's third round on the command line: progress that does not lie, defaults that
follow the testbed, defaults typed as shown, the grammar everywhere, messages and tables."""

from __future__ import annotations

import io
import json
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


@pytest.mark.parametrize(
    "extra",
    [
        ["--duration", "300"],
        ["--seeds", "4"],
        ["--start", "auto"],
        ["--initial-rate", "0", "0", "0"],
    ],  # fmt: skip
    ids=["duration", "seeds", "start", "initial-rate"],
)
def test_two_step_accepts_a_default_typed_as_shown(extra, tmp_path, capsys):
    args = ["balance", "seed004-platform", "--two-step", *extra, "--json", str(tmp_path / "t.json")]
    assert run(args) == 0, capsys.readouterr().err


def test_two_step_still_refuses_a_value_it_would_ignore(capsys):
    assert run(["balance", "seed004-platform", "--two-step", "--duration", "5"]) == 2
    assert "--duration: not used with --two-step" in capsys.readouterr().err


def test_identify_accepts_its_default_form_where_no_regression_runs(tmp_path, capsys):
    log = tmp_path / "slew.csv"
    assert run(["simulate", "cmg-yaw", "--duration", "10", "-o", str(log)]) == 0
    assert run(["identify", "cmg-yaw", str(log), "--form", "integrated"]) == 0
    capsys.readouterr()
    assert run(["identify", "cmg-yaw", str(log), "--form", "acceleration"]) == 2
    assert "--form: applies only to --method equation-error" in capsys.readouterr().err
