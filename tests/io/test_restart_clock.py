"""Two runs joined in one file whose second clock restarts at an earlier time, not at 0.

A recorder that keeps its clock between runs, or restarts it at an arbitrary value,
still joins two runs: time steps back to some earlier value and runs on from there.
``log check`` (and every command reading the log) and ``log import`` say "two runs:
split at row N" as they do for a clock that restarts at 0; a repeated time, two swapped
rows or one misplaced row is not a restart and is named as a time that does not increase.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML

from airbearing.io.log import restarts_at

N = 300  # rows: 30 s at the rig's 10 Hz


@pytest.fixture
def rig(tmp_path):
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    return tb


def _one_line(capsys, code: int) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    return err[0]


def test_the_rule_on_small_clocks():
    t = np.arange(10.0)
    assert restarts_at(np.r_[t, 0.0, 1.0, 2.0], 10, 0)  # back to 0
    assert restarts_at(np.r_[t, 4.0, 5.0, 6.0], 10, 0)  # back to 4 s, not 0
    assert restarts_at(np.r_[t, 4.0], 10, 0)  # the last row: no next row to undo it
    assert not restarts_at(np.r_[t[:5], 5.5, 5.0, t[6:]], 6, 0)  # two rows swapped
    assert not restarts_at(np.r_[t[:5], 99.0, t[5:]], 6, 0)  # one row from far ahead
    assert not restarts_at(np.r_[t[:5], -3.0, t[5:]], 5, 0)  # one row from far back
    assert not restarts_at(np.r_[t[:5], 4.0, t[5:]], 5, 0)  # a repeated time
    assert not restarts_at(np.r_[0.0, 5.0, 1.0, 2.0], 2, 1)  # a run of one row before it


def test_log_check_names_the_split_of_a_clock_restarting_above_zero(tmp_path, rig, capsys):
    t = np.arange(N) * 0.1
    t[150:] -= 7.0  # the second run's clock starts at 8.0 s, after 14.9 s
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": t, "yaw": 0.2 * np.arange(N) * 0.1}).to_csv(path, index=False)
    js = tmp_path / "c.json"
    line = _one_line(capsys, run(["log", "check", str(rig), str(path), "--json", str(js)]))
    assert "row 150" in line and "two runs in one file: split at row 150" in line, line
    assert not js.exists()


def test_two_swapped_rows_are_not_two_runs(tmp_path, rig, capsys):
    t = np.arange(N) * 0.1
    t[[100, 101]] = t[[101, 100]]
    path = tmp_path / "log.csv"
    pd.DataFrame({"t": t, "yaw": 0.2 * np.arange(N) * 0.1}).to_csv(path, index=False)
    line = _one_line(capsys, run(["log", "check", str(rig), str(path)]))
    assert "time must be strictly increasing" in line and "restarts" not in line, line


def _export(path, t_s: np.ndarray, yaw_deg: np.ndarray) -> None:
    pairs = enumerate(zip(t_s, yaw_deg, strict=True))
    rows = [f"{i},{float(t) * 1e3!r},{float(y)!r}" for i, (t, y) in pairs]
    path.write_text("Frame,Time (ms),Yaw (deg)\n" + "\n".join(rows) + "\n")


def test_import_refuses_then_splits_a_clock_restarting_above_zero(tmp_path, rig, capsys):
    t = np.arange(N) * 0.1
    t[200:] -= 12.5  # the second run's clock restarts at 7.5 s, after 19.9 s
    yaw = np.linspace(0.0, 300.0, N)
    raw = tmp_path / "raw.csv"
    _export(raw, t, yaw)
    before = raw.read_bytes()
    mapping = tmp_path / "map.toml"
    mapping.write_text(MOCAP_MAP_TOML)
    out = tmp_path / "log.csv"
    args = ["log", "import", str(rig), str(raw), "--map", str(mapping), "-o", str(out)]
    line = _one_line(capsys, run(args))
    assert "time restarts at row 200" in line and "two runs" in line, line
    assert 'restart = "split"' in line and not out.exists()

    mapping.write_text('restart = "split"\n' + MOCAP_MAP_TOML)
    assert run(args) == 0
    assert "run 2: raw rows 200-299" in capsys.readouterr().out
    one, two = pd.read_csv(tmp_path / "log-run1.csv"), pd.read_csv(tmp_path / "log-run2.csv")
    assert (len(one), len(two)) == (200, 100)
    # the second run keeps its own clock (7.5 s at its first row)
    assert two["t"].iloc[0] == pytest.approx(7.5, abs=1e-9)
    assert raw.read_bytes() == before
