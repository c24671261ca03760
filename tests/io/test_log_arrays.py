"""A log read from a file of float64 columns holds arrays, not a DataFrame (io.log_checks).

The same log read from the same file must be the same log whichever way it is held: the
same ``Log.data``, the same accessors, the same errors and messages; and reading it, its
quality check and the equation-error identification must not load pandas (the reason the
arrays exist: 0.4-0.5 s of CPU of ``airbearing identify``).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from airbearing.errors import InputError
from airbearing.io import Log, load_testbed, read_log, write_log
from airbearing.io.log import BadCellsError

PLATFORM = load_testbed("platform-3dof")  # dof 3, sensors.rate 20 Hz
CMG_YAW = load_testbed("cmg-yaw")  # dof 1, sensors.rate 20 Hz


def _platform_frame(n: int = 60, seed: int = 0) -> pd.DataFrame:
    """A valid platform log of float64 columns only (an extra one included)."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    data = {"t": 0.05 * np.arange(n)}
    data |= dict(zip(("qw", "qx", "qy", "qz"), q.T, strict=True))
    for axis in ("x", "y", "z"):
        data["w" + axis] = 0.1 * rng.normal(size=n)
    for i in (1, 2, 3):
        data[f"s{i}"] = np.full(n, 0.01)
    data["true_wz"] = rng.normal(size=n)
    return pd.DataFrame(data)


def _as_frame(log: Log) -> Log:
    """The same samples held as a DataFrame (``Log(data)`` validates a table)."""
    return Log(log.data.copy(), source=log.source, testbed=log.testbed)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_float_log_read_as_arrays_is_the_log_read_as_a_table(tmp_path, suffix):
    path = write_log(_platform_frame(), tmp_path / f"run{suffix}")
    log = read_log(path, PLATFORM)
    assert log._arrays is not None  # held as arrays until .data is asked for
    table = _as_frame(read_log(path, PLATFORM))
    assert log.n == table.n == 60 and log.has("true_wz") and not log.has("wc1")
    for get in (Log.rates, Log.quaternions, Log.sliders, Log.dipoles, Log.wheel_speeds):
        a, b = get(log), get(table)
        assert (a is None and b is None) or np.array_equal(a, b)
    assert np.array_equal(log.column("true_wz"), table.column("true_wz"))
    assert np.array_equal(log.t, table.t) and log.segments == table.segments
    assert repr(log) == repr(table)
    assert log.quality == table.quality
    pd.testing.assert_frame_equal(log.data, table.data)  # built on first use
    assert log._arrays is None  # from here on the DataFrame is the log


def test_an_extra_column_with_a_bad_cell_says_so_as_the_table_does(tmp_path):
    df = _platform_frame()
    df.loc[7, "true_wz"] = np.nan  # not a FORMATS.md column: read, and refused when used
    path = write_log(df, tmp_path / "run.parquet")
    log = read_log(path, PLATFORM)
    with pytest.raises(BadCellsError) as arrays:
        log.column("true_wz")
    with pytest.raises(BadCellsError) as table:
        _as_frame(log).column("true_wz")
    assert str(arrays.value) == str(table.value)
    assert "row 7, column 'true_wz'" in str(arrays.value)


def test_a_bad_log_read_as_arrays_raises_the_tables_message(tmp_path):
    df = _platform_frame()
    df.loc[30, "t"] = df.loc[29, "t"]  # time stands still: no array shortcut changes the words
    path = tmp_path / "run.parquet"
    df.to_parquet(path)  # (write_log validates: it would refuse this log)
    with pytest.raises(InputError) as read:
        read_log(path, PLATFORM)
    with pytest.raises(InputError) as table:
        Log(df, source=str(path), testbed=PLATFORM)
    assert str(read.value) == str(table.value)
    assert "row 30, column 't': time must be strictly increasing" in str(read.value)


def test_a_wrapped_yaw_is_unwrapped_the_same_way_on_arrays(tmp_path):
    n = 80
    t = 0.05 * np.arange(n)
    yaw = np.mod(0.9 * t + np.pi, 2 * np.pi) - np.pi  # wrapped to [-pi, pi): jumps once
    rng = np.random.default_rng(3)
    df = pd.DataFrame({"t": t, "wz": np.full(n, 0.9), "yaw": yaw})
    for i in range(1, 5):
        df[f"d{i}"] = rng.normal(size=n)
    path = tmp_path / "run.parquet"
    df.to_parquet(path)
    log = read_log(path, CMG_YAW)
    table = Log(df, source=str(path), testbed=CMG_YAW)
    assert np.array_equal(log.yaw(), table.yaw())
    assert np.all(np.abs(np.diff(log.yaw())) < 0.1)  # unwrapped: no 2 pi jump left
    assert log.data.attrs == table.data.attrs and table.data.attrs  # the rows said


def test_reading_checking_and_identifying_a_float_log_loads_no_pandas(tmp_path):
    from airbearing.analysis.simulation.scenarios import free_oscillation

    tb = load_testbed("platform-3dof")
    log = free_oscillation(tb, initial_rate=(0.3, 0.2, -1.5), duration=30.0, seed=0).log
    paths = [write_log(log, tmp_path / f"run{i}{s}") for i, s in enumerate((".csv", ".parquet"))]
    code = (
        "import sys\n"
        "from airbearing.analysis.identification.equation_error import identify_equation_error\n"
        "from airbearing.analysis.identification.options import columns_used\n"
        "from airbearing.io.log import read_log\n"
        "from airbearing.io.testbed import load_testbed\n"
        "tb = load_testbed('platform-3dof')\n"
        "logs = [read_log(p, tb, columns=columns_used(tb)) for p in sys.argv[1:]]\n"
        "[log.quality for log in logs]\n"
        "identify_equation_error(tb, logs, known_offset_xy=(4e-4, 7e-4))\n"
        "print('pandas' in sys.modules)\n"
    )
    src = str(Path(__file__).resolve().parents[2] / "src")
    out = subprocess.run(
        [sys.executable, "-c", code, *map(str, paths)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONPATH": src},
    )
    assert out.stdout.strip().splitlines()[-1] == "False"
