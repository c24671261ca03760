"""Messy lab logs, round 3: a log at another rate than its testbed's, two runs joined with
continuous time, a logger that halves its rate mid-log, Excel's byte-order mark, tabs.

The logs are exact motions in closed form (tests/test_log_quality.py) with white noise of
the testbed's size; the defects are made as a lab makes them (time divided by 1000, a
second run appended with ``t += duration``, every other sample dropped after a time).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_log_quality import mocap_yaw_log, platform, tumble_log

from airbearing.errors import InputError
from airbearing.io import Log
from airbearing.io.log import read_log


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
