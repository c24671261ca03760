"""Human output: aligned tables with units, no reprs, one compile notice, an honest time left,
and no warning or solver chatter on the terminal unless --verbose."""

from __future__ import annotations

import io
import math
import os
import re
import sys
import warnings

import pytest
from cli_run import run

from airbearing.cli import chatter_to_debug_log, show_progress
from airbearing.cli.tables import human_summary, matrix_table
from airbearing.progress import TimeLeft

#: What must never reach a person: dict/list reprs, numpy reprs.
_REPRS = re.compile(r"[{}\[\]]|'|np\.float")
_NUMBER = re.compile(r"\d+\.\d+|\d+")


class _Repr:
    """Finds a repr, or a number with more than 4 significant digits (a 17-digit float)."""

    @staticmethod
    def search(text: str):
        found = _REPRS.search(text)
        if found:
            return found
        for m in _NUMBER.finditer(text):
            digits = m.group().replace(".", "").lstrip("0")
            if "." in m.group() and len(digits) > 4:
                return m
        return None


_REPR = _Repr()

TWO_STEP = {  # the shape of TwoStepResult.to_json(), values as a run gives them
    "testbed": "seed004-platform",
    "method": "lyapunov",
    "ke_std_before": 0.0012345678901234567,
    "ke_std_after": 3.0864197530864196e-06,
    "ke_reduction": 0.9975,
    "vertical_offset_identified_m": -0.0026012345678901234,
    "cm_offset_identified_m": [2.998e-06, -1.2345678901234567e-06, -0.0026012345678901234],
    "cm_offset_true_m": [3e-06, -1.2e-06, -0.0026],
    "inertia_identified": [[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]],
    "identify_method": "output-error",
    "identify_warnings": [],
    "known_displacement_m": [0.005, 0.005, 0.0],
    "in_plane_known": True,
    "sliders_step1_m": [0.0011, -0.0023, 0.0],
    "sliders_final_m": [0.0011, -0.0023, 0.0031],
    "residual_offset_step1_m": [1e-07, 2e-07, -0.0026],
    "residual_offset_m": [1e-07, 2e-07, 5e-08],
    "g_perp_rms_step1": 0.000123456789,
    "balance_duration_s": 300.0,
    "seed": 0,
}


def _aligned(block: str) -> bool:
    """Every line of a table fits under its rule (the second line)."""
    lines = block.splitlines()
    if len(lines) < 2 or not set(lines[1]) <= {"-", " "}:
        return True
    return all(len(line) <= len(lines[1]) for line in lines)


def test_two_step_summary_is_tables_with_units_and_um():
    text = human_summary(TWO_STEP)
    assert not _REPR.search(text), _REPR.search(text)
    row = next(line for line in text.splitlines() if line.startswith("cm offset identified"))
    assert "2.998" in row and row.rstrip().endswith("um")  # 2.998e-06 m shown as 2.998 um
    assert "vertical offset identified" in text and "-2601" in text  # um
    assert all(_aligned(b) for b in text.split("\n\n"))


def test_compare_prints_tables_not_reprs(capsys):
    rc = run(["balance", "seed000-tabletop", "--compare", "mechanical,mixed", "--seeds", "1",
              "--duration", "20"])  # fmt: skip
    out = capsys.readouterr().out
    assert rc == 0
    assert "offset (mm)" in out and "g perp rms" in out
    tables = [b for b in out.split("\n\n") if not b.startswith("verdict")]
    assert not any(_REPR.search(b) for b in tables), [_REPR.search(b) for b in tables]
    assert all(_aligned(b) for b in tables)


def test_identify_matrix_is_aligned():
    text = matrix_table(
        [[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]],
        "kg m^2",
        std=[[1e-5, 2e-6, 3e-7]] * 3,
    )
    lines = text.splitlines()
    assert _aligned(text) and "(kg m^2)" in lines[0]
    # right-aligned numbers: every row ends at the same column
    assert len({len(line) for line in lines}) == 1


def test_time_left_never_grows_by_more_than_its_uncertainty():
    # steps of 1 s, then the work slows to 10 s a step (the demo's 8 -> 26 -> 38 s)
    times = [1.0 * k for k in range(1, 6)] + [5.0 + 10.0 * k for k in range(1, 6)]
    left = TimeLeft(0.0)
    previous = None
    for done, now in enumerate(times, start=1):
        shown = left.update(done, 20, now)
        if previous is not None:
            (was, unc), then = previous
            assert shown[0] <= max(was - (now - then), 0.0) + unc + 1e-12
        previous = shown, now
    assert left.update(0, 20, 1.0) is None and left.update(20, 20, 1.0) is None


def test_time_left_counts_down_on_steady_work():
    left = TimeLeft(0.0)
    shown = [left.update(k, 10, float(k))[0] for k in range(1, 10)]
    assert shown == pytest.approx([9 - k for k in range(9)])


def test_compile_notice_once_per_process(monkeypatch):
    buf = io.StringIO()
    monkeypatch.setattr(sys, "stderr", buf)
    monkeypatch.setattr(show_progress, "PLAIN_DELAY", 0.0)
    monkeypatch.setitem(show_progress._COMPILE_NOTICE, "shown", False)
    for _ in range(2):  # two commands of one process (the demo's sections)
        with show_progress.progress_display("demo") as progress:
            for k in range(20):
                progress(f"compiling closed_loop_step_x{k} to C (once per model structure)")
                progress(f"section {k}")
    assert buf.getvalue().count("compiling") == 1


def test_each_compile_sink_is_told_once():
    from airbearing.models import compiled as cm

    told = []

    def sink(what, done=None, total=None):
        told.append(what)

    with cm.compile_notices(sink):
        cm._announce("compiling a to C", None)
        cm._announce("compiling b to C", None)
    assert told == ["compiling a to C"]


def test_warnings_and_fd_chatter_go_to_the_debug_log(capfd):
    with chatter_to_debug_log(False, fds=True) as log:
        warnings.warn("overflow encountered in square", RuntimeWarning, stacklevel=1)
        os.write(2, b"NaN detected for output\n")  # CasADi/IPOPT write to the fd itself
        os.write(1, b"iter    objective\n")
        print("airbearing: the one line a person reads", file=sys.stderr)
        assert math.isfinite(1.0)
    err = capfd.readouterr()
    assert "NaN detected" not in err.err and "overflow" not in err.err
    assert "iter" not in err.out
    assert "the one line a person reads" in err.err
    text = log.read_text()
    assert "NaN detected" in text and "overflow encountered" in text
    log.unlink()


def test_verbose_shows_the_chatter(capfd):
    with chatter_to_debug_log(True, fds=True):
        warnings.warn("overflow encountered in square", RuntimeWarning, stacklevel=1)
        os.write(2, b"NaN detected for output\n")
    err = capfd.readouterr().err
    assert "NaN detected" in err and "overflow" in err


def test_verbose_is_a_global_option(capsys):
    assert run(["--verbose", "cmg", "size"]) == 0
    assert "0.8661" in capsys.readouterr().out
