"""Messy lab logs, round 3: a log at another rate than its testbed's, two runs joined with
continuous time, a logger that halves its rate mid-log, Excel's byte-order mark, tabs.

The logs are exact motions in closed form (tests/io/test_log_quality.py) with white noise of
the testbed's size; the defects are made as a lab makes them (time divided by 1000, a
second run appended with ``t += duration``, every other sample dropped after a time).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from test_log_quality import MOTIONS, mocap_yaw_log, platform, tumble_log

from airbearing.cli.log import SHOWN_SEGMENTS
from airbearing.errors import InputError
from airbearing.io import Log
from airbearing.io.log import read_log
from airbearing.io.testbed import write_testbed


def _message(e) -> str:
    return str(e.value)


# ----------------------------------------------------------------------------
# 1. the sample interval against the testbed's rate


@pytest.mark.parametrize(
    ("log_rate", "tb_rate"), [(20.0, 10.0), (50.0, 20.0), (10.0, 20.0)], ids=str
)
def test_log_at_another_rate_is_one_error(log_rate, tb_rate):
    df, _ = tumble_log(seed=1, n=300, rate=log_rate, jitter=0.0)
    with pytest.raises(InputError) as e:
        Log(df, "run.csv", platform(tb_rate, 4e-4, 1e-3))
    text = _message(e)
    if log_rate > tb_rate:
        assert text.startswith("run.csv: column 't': median sample interval")
    else:  # every interval is a gap: that error, with the same diagnosis
        assert text.startswith("run.csv: the log is all gaps")
    assert f"sensors.rate = {tb_rate:g} Hz" in text and f"{1 / log_rate:g} s" in text
    assert "another testbed's log" in text and "\n" not in text
    Log(df, "run.csv", platform(log_rate, 4e-4, 1e-3))  # its own testbed takes it


def test_rate_within_the_factor_is_taken():
    # 1.4 x the period: every interval still within the gap rule's 1.5 (jitter, not gaps)
    df, _ = tumble_log(seed=1, n=300, rate=20.0 / 1.4, jitter=0.0)
    assert Log(df, "run.csv", platform(20.0, 4e-4, 1e-3)).quality.n_segments == 1


def test_time_in_s_read_as_ms_names_the_unit(tmp_path):
    df, tb = mocap_yaw_log(seed=2, n=400)
    df["t"] = df["t"] / 1000.0  # the map said ms, the file was in s
    path = tmp_path / "run.csv"
    df.to_csv(path, index=False)
    with pytest.raises(InputError) as e:
        read_log(path, tb)
    assert "median sample interval 0.0001 s" in _message(e)
    assert 'looks like s read as ms: [units] t = "s"' in _message(e)


def test_integer_ms_time_gets_the_import_hint(tmp_path):
    df, tb = mocap_yaw_log(seed=2, n=400)
    df["t"] = (df["t"] * 1000).round().astype(int)
    path = tmp_path / "run.csv"
    df.to_csv(path, index=False)
    with pytest.raises(InputError) as e:
        read_log(path, tb)
    assert 'looks like ms: use airbearing log import with [units] t = "ms"' in _message(e)


@pytest.mark.parametrize("with_testbed", [False, True])
def test_import_of_a_file_in_s_with_a_map_in_ms_is_one_error(tmp_path, capsys, with_testbed):
    from rigs import MOCAP_MAP_TOML

    df, tb = mocap_yaw_log(seed=2, n=400)
    raw, mp, tb_path = tmp_path / "raw.csv", tmp_path / "map.toml", tmp_path / "tb.toml"
    pd.DataFrame({"Time (ms)": df["t"], "Yaw (deg)": np.degrees(df["yaw"])}).to_csv(
        raw, index=False
    )  # the clock exported in s, the map says ms
    mp.write_text(MOCAP_MAP_TOML)
    write_testbed(tb, tb_path)
    out = tmp_path / "log.csv"
    args = ["log", "import", *([str(tb_path)] if with_testbed else []), str(raw)]
    assert run([*args, "--map", str(mp), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "median interval 0.0001 s" in err and "is the time column in s?" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


# ----------------------------------------------------------------------------
# 4. byte-order mark, tabs


def test_byte_order_mark_is_read(tmp_path):
    df, tb = mocap_yaw_log(seed=3, n=300)
    path = tmp_path / "run.csv"
    df.to_csv(path, index=False, encoding="utf-8-sig")
    log = read_log(path, tb)
    assert list(log.data.columns) == ["t", "yaw"]
    np.testing.assert_array_equal(log.t, df["t"].to_numpy())


@pytest.mark.parametrize(("sep", "name"), [("\t", "tabs"), (";", "semicolons")])
def test_other_separator_is_named(tmp_path, sep, name):
    df, tb = mocap_yaw_log(seed=3, n=300)
    path = tmp_path / "run.csv"
    df.to_csv(path, index=False, sep=sep)
    with pytest.raises(InputError) as e:
        read_log(path, tb)
    assert _message(e).startswith(f"{path}: line 1: not comma separated: {name} found")
    assert "log import" in _message(e)


# ----------------------------------------------------------------------------
# 2. two runs joined with continuous time: a step, the segment breaks there


def _joined(n=1200):
    first, tb = tumble_log(seed=4, n=n, jitter=0.0)
    second, _ = tumble_log(seed=5, n=n, w0=(0.3, -0.5, 1.1), jitter=0.0)
    second["t"] += first["t"].iloc[-1] + 1.0 / tb.sensors.rate  # time made continuous
    return pd.concat([first, second], ignore_index=True), tb


def test_two_runs_joined_break_the_segment_at_the_join():
    df, tb = _joined()
    q = Log(df, "run.csv", tb).quality
    assert [d.row for d in q.discontinuities] == [1200]
    assert q.segments == ((0, 1200), (1200, 2400))
    assert set(q.discontinuities[0].columns) >= {"qw", "qx", "qy", "qz"}
    assert q.outlier_rows == () and q.unexplained_rows == ()  # nothing else is made of it
    out = q.to_json()
    assert out["discontinuity_rows"] == [1200] and out["segment_rows"][1] == [1200, 2400]


def test_mocap_yaw_with_one_sample_cut_out_breaks_there():
    # the milder splice: one sample removed, the time column made continuous again
    df, tb = mocap_yaw_log(seed=8, n=2000)
    spliced = pd.concat([df.iloc[:1500], df.iloc[1501:]], ignore_index=True)
    spliced["t"] = df["t"].iloc[: len(spliced)].to_numpy()
    q = Log(spliced, "run.csv", tb).quality
    assert [d.row for d in q.discontinuities] == [1500]
    assert q.segments == ((0, 1500), (1500, 1999))
    assert Log(df, "run.csv", tb).quality.discontinuities == ()  # the uncut log has none


@pytest.mark.parametrize("make", MOTIONS, ids=lambda f: f.__name__)
def test_fast_smooth_motion_is_no_step(make):
    # a 4 rad/s spin at 10 Hz, a 1.6 rad/s swing, a spin-down seen by motion capture:
    # smooth, however fast for the sample rate
    df, tb = make(seed=12)
    assert Log(df, "run.csv", tb).quality.discontinuities == ()


def test_cli_check_names_the_step_and_import_says_it(tmp_path, capsys):
    df, tb = _joined()
    path, tb_path = tmp_path / "run.csv", tmp_path / "tb.toml"
    df.to_csv(path, index=False)
    write_testbed(tb, tb_path)
    assert run(["log", "check", str(tb_path), str(path), "--json", str(tmp_path / "c.json")]) == 0
    text = capsys.readouterr().out
    assert "step      row 1200" in text and "a new segment starts" in text
    assert "segments  2" in text
    summary = json.loads((tmp_path / "c.json").read_text())
    assert summary["discontinuity_rows"] == [1200]
    page = tmp_path / "plot.html"
    assert run(["log", "plot", str(tb_path), str(path), "-o", str(page)]) == 0
    # the page says it in the words of `log import` (LogQuality.findings)
    assert "Discontinuity: row 1200: step between rows 1199 and 1200" in page.read_text()


# ----------------------------------------------------------------------------
# 3. a logger that halves its rate mid-log


def _halved():
    df, tb = tumble_log(seed=6, n=1200, jitter=0.0)
    return pd.concat([df.iloc[:600], df.iloc[600:].iloc[::2]], ignore_index=True), tb


def test_rate_drop_is_one_statement_and_the_segments_are_kept():
    df, tb = _halved()
    q = Log(df, "run.csv", tb).quality
    assert len(q.rate_changes) == 1
    change = q.rate_changes[0]
    assert change["first_row"] == 601 and change["last_row"] == 899
    assert change["interval"] == pytest.approx(0.1, rel=1e-9)
    assert "10 Hz" in change["reason"] and "from row 601" in change["reason"]
    assert q.n_segments == 300  # every 10 Hz interval is a gap: nothing filled


def test_cli_check_caps_the_segment_list_and_plot_draws_every_row(tmp_path, capsys):
    from airbearing.reporting.log_plot import log_figure

    df, tb = _halved()
    path, tb_path = tmp_path / "run.csv", tmp_path / "tb.toml"
    df.to_csv(path, index=False)
    write_testbed(tb, tb_path)
    assert run(["log", "check", str(tb_path), str(path), "--json", str(tmp_path / "c.json")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len([ln for ln in lines if " rows " in ln and "#" in ln]) == SHOWN_SEGMENTS
    assert sum("more segment(s) (all in the JSON)" in ln for ln in lines) == 1
    assert sum("the sample interval is 0.1 s (10 Hz)" in ln for ln in lines) == 1
    assert len(lines) < 40
    assert len(json.loads((tmp_path / "c.json").read_text())["segment_rows"]) == 300
    log = read_log(path, tb)
    fig = log_figure(log, log.quality)
    drawn = set()
    for line in fig.axes[0].get_lines():  # the quaternion panel: lines and lone dots
        x = np.asarray(line.get_xdata(), dtype=float)
        drawn |= set(np.round(x[np.isfinite(x)], 9))
    assert drawn >= set(np.round(log.t, 9))  # every row of the log is on the figure


@pytest.mark.parametrize(("method", "seed"), [("mechanical", 1), ("lyapunov", 1)])
def test_stepper_moves_of_a_balancing_run_are_no_step(method, seed):
    # stepper sliders moving at every sample: each move is an impulse on the platform
    # (a change of slope of its noise-free attitude), smooth motion all the same
    from airbearing.analysis.balancing.runs import run_balancing
    from airbearing.io.testbed import load_testbed

    log = run_balancing(load_testbed("seed000-tabletop"), method, duration=300.0, seed=seed)
    q = log.result.log.quality
    assert q.discontinuities == () and q.n_segments == 1


# ----------------------------------------------------------------------------
# 5. what log check says identify can use is what identify does


@pytest.mark.parametrize("n", [5, 3])
def test_check_says_of_a_short_cmg_log_what_identify_does(n):
    from airbearing.analysis.identification.cmg_inertia import identify_cmg_inertia
    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.testbed import load_testbed
    from airbearing.io.tool_use import tool_use

    tb = load_testbed("cmg-yaw")
    full = slew(tb, angle_deg=90, duration=5, seed=1).log
    log = Log(full.data.iloc[10 : 10 + n], "short.csv", tb)
    ok, why = tool_use(log, log.quality)["identify"]
    try:
        identify_cmg_inertia(tb, [log])
        answered = True
    except InputError:
        answered = False
    assert ok == answered, why
