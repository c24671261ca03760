"""Tests of airbearing.io.log (FORMATS.md, "Log (CSV or Parquet)")."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from airbearing.errors import InputError
from airbearing.io import (
    LOG_COLUMNS,
    REQUIRED_COLUMNS,
    Log,
    load_testbed,
    read_log,
    validate_log,
    write_log,
)

PLATFORM = load_testbed("platform-3dof")  # dof 3, sensors.rate 20 Hz
CMG_YAW = load_testbed("cmg-yaw")  # dof 1, sensors.rate 20 Hz
SRC = "run.csv"


def platform_frame(n: int = 20, seed: int = 0) -> pd.DataFrame:
    """A valid platform log: unit quaternions, rates, sliders, dipoles, fields, extras."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    data = {"t": 0.05 * np.arange(n) + rng.uniform(-0.01, 0.01, n)}
    data |= dict(zip(("qw", "qx", "qy", "qz"), q.T, strict=True))
    for name, scale in (("w", 0.1), ("s", 0.03), ("m", 1.0), ("b", 6e-4)):
        axes = ("x", "y", "z") if name != "s" else ("1", "2", "3")
        for axis in axes:
            data[name + axis] = scale * rng.normal(size=n)
    data["comment"] = [f"sample {i}, ok" for i in range(n)]
    data["counter"] = np.arange(n)
    return pd.DataFrame(data)


def cmg_frame(n: int = 20, seed: int = 1) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    data = {"t": 0.05 * np.arange(n), "wz": rng.normal(size=n), "yaw": rng.normal(size=n)}
    for i in range(1, 5):
        data[f"d{i}"] = rng.normal(size=n)
        data[f"dd{i}"] = rng.normal(size=n)
    data["yaw_ref"] = np.full(n, np.pi)
    return pd.DataFrame(data)


def message(excinfo) -> str:
    return str(excinfo.value)


# ----------------------------------------------------------------------------
# the Log object


def test_log_accessors_platform():
    df = platform_frame()
    log = Log(df, source=SRC, testbed=PLATFORM)
    assert log.n == len(log) == 20 and log.source == SRC and log.testbed is PLATFORM
    np.testing.assert_array_equal(log.t, df["t"].to_numpy())
    assert log.dt == pytest.approx(0.05, abs=0.02)
    assert log.rates().shape == (20, 3)
    np.testing.assert_array_equal(log.rates(), df[["wx", "wy", "wz"]].to_numpy())
    assert log.quaternions().shape == (20, 4)
    np.testing.assert_array_equal(log.sliders(), df[["s1", "s2", "s3"]].to_numpy())
    np.testing.assert_array_equal(log.dipoles(), df[["mx", "my", "mz"]].to_numpy())
    np.testing.assert_array_equal(log.fields(), df[["bx", "by", "bz"]].to_numpy())
    assert log.gimbals() is None and log.gimbal_rates() is None and log.yaw() is None
    assert log.columns(["wz", "counter"]).shape == (20, 2)
    assert log.has("t", "comment") and not log.has("t", "yaw")
    assert list(log.data["comment"]) == list(df["comment"])  # extra columns kept
    assert log.data["t"].dtype == np.float64
    log.rates()[0, 0] = 99.0  # a copy
    assert log.data["wx"].iloc[0] != 99.0
    with pytest.raises(InputError, match=r"run\.csv: no column 'yaw'"):
        log.column("yaw")
    with pytest.raises(InputError, match="column 'comment': expected a finite number"):
        log.column("comment")


def test_log_accessors_cmg():
    df = cmg_frame()
    log = Log(df, testbed=CMG_YAW)
    assert log.rates().shape == (20, 1)
    np.testing.assert_array_equal(log.rates()[:, 0], df["wz"].to_numpy())
    assert log.gimbals().shape == (20, 4) and log.gimbal_rates().shape == (20, 4)
    np.testing.assert_array_equal(log.yaw(), df["yaw"].to_numpy())
    np.testing.assert_array_equal(log.yaw_ref(), np.full(20, np.pi))
    assert log.quaternions() is None and log.sliders() is None and log.dipoles() is None
    # dof 1 takes wz even when the IMU logged all three axes
    df3 = df.assign(wx=0.0, wy=0.0)
    assert Log(df3, testbed=CMG_YAW).rates().shape == (20, 1)
    assert Log(df3).rates().shape == (20, 3)  # without a testbed: all that is there


def test_integer_columns_become_float_and_index_is_reset():
    df = pd.DataFrame({"t": [0, 1, 2], "wz": [1, 2, 3]}, index=[10, 20, 30])
    log = Log(df)
    assert log.data["t"].dtype == np.float64 and log.data["wz"].dtype == np.float64
    assert list(log.data.index) == [0, 1, 2]


def test_required_columns():
    assert REQUIRED_COLUMNS() == ["t"]
    assert REQUIRED_COLUMNS(PLATFORM) == [
        "t", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "s1", "s2", "s3"
    ]  # fmt: skip
    assert REQUIRED_COLUMNS(CMG_YAW) == ["t", "wz", "yaw", "d1", "d2", "d3", "d4"]
    assert set(REQUIRED_COLUMNS(PLATFORM)) <= set(LOG_COLUMNS)


def test_required_columns_passive_and_motion_capture():
    # FORMATS.md: no s1..s3 without [masses]; no rate columns when sensors.gyro = false
    passive = PLATFORM.replace(masses=None, magnetorquers=None)
    assert REQUIRED_COLUMNS(passive) == ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    mocap = passive.replace(sensors=passive.sensors.__class__(rate=20.0, gyro=False))
    assert REQUIRED_COLUMNS(mocap) == ["t", "qw", "qx", "qy", "qz"]
    yaw_only = CMG_YAW.replace(sensors=CMG_YAW.sensors.__class__(gyro=False))
    assert REQUIRED_COLUMNS(yaw_only) == ["t", "yaw", "d1", "d2", "d3", "d4"]
    df = platform_frame().drop(columns=["s1", "s2", "s3", "wx", "wy", "wz"])
    assert Log(df, SRC, mocap).rates() is None
    with pytest.raises(InputError, match="missing column 'wx'"):
        Log(df, SRC, PLATFORM)


def test_dof1_accepts_quaternion_instead_of_yaw():
    df = cmg_frame().drop(columns="yaw").assign(qw=1.0, qx=0.0, qy=0.0, qz=0.0)
    assert Log(df, testbed=CMG_YAW).quaternions().shape == (20, 4)


# ----------------------------------------------------------------------------
# validation rules (DataFrame input): each names the row and the column


def with_value(df: pd.DataFrame, row: int, column: str, value) -> pd.DataFrame:
    df = df.copy()
    if not isinstance(value, float):
        df[column] = df[column].astype(object)
    df.loc[row, column] = value
    return df


def test_missing_t():
    with pytest.raises(InputError) as e:
        validate_log(cmg_frame().drop(columns="t"), SRC)
    assert "run.csv: missing column 't'" in message(e) and "wz" in message(e)


def test_too_few_rows():
    with pytest.raises(InputError, match=r"run\.csv: a log needs at least 2 rows, got 1"):
        validate_log(cmg_frame(n=1), SRC)


@pytest.mark.parametrize(
    ("value", "got"),
    [(np.nan, "NaN"), (np.inf, "inf"), (-np.inf, "-inf"), ("abc", "'abc'"), (None, "missing")],
    ids=["nan", "inf", "-inf", "text", "none"],
)
def test_non_finite_or_non_numeric_cell(value, got):
    df = with_value(cmg_frame(), 6, "d3", value)  # rows are 0-based data rows (FORMATS.md)
    with pytest.raises(InputError) as e:
        validate_log(df, SRC)
    assert "run.csv: row 6, column 'd3': expected a finite number" in message(e)
    assert got in message(e)


def test_first_bad_cell_over_all_columns_is_reported():
    df = with_value(with_value(cmg_frame(), 9, "wz", np.nan), 4, "dd4", np.nan)
    with pytest.raises(InputError, match=r"row 4, column 'dd4'"):
        validate_log(df, SRC)


def test_bad_value_in_extra_column_is_ignored():
    df = cmg_frame().assign(note=np.nan, flag=True)
    assert Log(df).data["note"].isna().all()


def test_boolean_column_is_not_numbers():
    df = cmg_frame().assign(wz=True)
    with pytest.raises(InputError, match=r"row 0, column 'wz': expected a finite number"):
        validate_log(df, SRC)


@pytest.mark.parametrize("later", [0.10, 0.05], ids=["backwards", "repeated"])
def test_time_strictly_increasing(later):
    df = cmg_frame()
    df.loc[3, "t"] = later  # row 3 follows row 2 at t = 0.10
    with pytest.raises(InputError) as e:
        validate_log(df, SRC)
    assert "run.csv: row 3, column 't': time must be strictly increasing" in message(e)
    assert f"t = {later!r} s follows t = 0.1 s of row 2" in message(e)


@pytest.mark.parametrize(
    ("testbed", "drop", "fragments"),
    [
        (PLATFORM, ["qx"], ["missing column 'qx'", "kind = 'platform', dof = 3"]),
        (PLATFORM, ["wy"], ["missing column 'wy'", "'platform-3dof'"]),
        (PLATFORM, ["s1", "s2", "s3"], ["missing column 's1'", "kind = 'platform'"]),
        (CMG_YAW, ["wz"], ["missing column 'wz'", "kind = 'cmg', dof = 1"]),
        (CMG_YAW, ["yaw"], ["missing column 'yaw'", "quaternion", "dof = 1"]),
        (CMG_YAW, [f"d{i}" for i in range(1, 5)], ["missing column 'd1'", "kind = 'cmg'"]),
    ],
    ids=["quaternion", "rates", "sliders", "wz", "yaw", "gimbals"],
)
def test_missing_column_for_testbed(testbed, drop, fragments):
    df = (platform_frame() if testbed is PLATFORM else cmg_frame()).drop(columns=drop)
    with pytest.raises(InputError) as e:
        validate_log(df, SRC, testbed)
    assert message(e).startswith("run.csv: ")
    for fragment in fragments:
        assert fragment in message(e)


@pytest.mark.parametrize(
    ("extra", "missing"),
    [
        ({"mx": 0.0}, "my, mz"),
        ({"bx": 0.0, "bz": 0.0}, "by"),
        ({"dd1": 0.0, "dd2": 0.0, "dd4": 0.0}, "dd3"),
        ({"qw": 1.0}, "qx, qy, qz"),
    ],
    ids=["dipole", "field", "gimbal-rates", "quaternion"],
)
def test_column_groups_all_or_none(extra, missing):
    df = pd.DataFrame({"t": [0.0, 0.05], "wz": [0.0, 0.0], **extra})
    with pytest.raises(InputError) as e:
        validate_log(df, SRC)
    assert f"run.csv: missing column(s) {missing}" in message(e)
    assert "all or none" in message(e)


@pytest.mark.parametrize(("step", "segments"), [(0.2, ((0, 5), (5, 20))), (0.01, ((0, 20),))])
def test_gap_splits_into_segments_and_short_interval_is_used(step, segments):
    # FORMATS.md: an interval > 1.5 / rate splits the log into segments, never an error;
    # an interval < 0.5 / rate (documented in io.log) is used with its logged time.
    df = cmg_frame()
    df.loc[5:, "t"] += step - 0.05  # the interval before row 5 is off
    log = Log(df, SRC, CMG_YAW)
    assert log.segments == segments
    np.testing.assert_array_equal(log.t, df["t"].to_numpy())


def test_jitter_within_half_period_is_one_segment():
    df = cmg_frame(n=200)
    rng = np.random.default_rng(3)
    df["t"] = np.cumsum(0.05 * (1 + rng.uniform(-0.49, 0.49, 200)))  # FORMATS.md: +-50 %
    assert Log(df, SRC, CMG_YAW).segments == ((0, 200),)


def test_all_gaps_is_one_error():
    df = cmg_frame(n=5)
    df["t"] = [0.0, 1.0, 2.0, 3.0, 4.0]  # every interval 20 periods at 20 Hz
    with pytest.raises(InputError) as e:
        validate_log(df, SRC, CMG_YAW)
    assert message(e).startswith("run.csv: the log is all gaps")
    assert "\n" not in message(e)
    validate_log(df, SRC)  # without a testbed there is no sample rate to judge gaps by
    df.loc[4, "t"] = 3.05  # one segment of 2 samples, but a median interval of 20 periods:
    with pytest.raises(InputError, match="median sample interval 1 s"):  # another rate
        Log(df, SRC, CMG_YAW)


def test_quaternion_norm():
    df = platform_frame()
    df.loc[11, "qw"] += 0.01
    with pytest.raises(InputError) as e:
        validate_log(df, SRC)
    assert "run.csv: row 11, columns qw, qx, qy, qz: expected a unit quaternion" in message(e)


def test_quaternion_norm_tolerance():
    # FORMATS.md rule: norm within 1e-3 of 1 passes
    df = platform_frame()
    df[["qw", "qx", "qy", "qz"]] *= 1 + 9e-4
    Log(df, testbed=PLATFORM)


def test_duplicate_column():
    df = pd.DataFrame([[0.0, 1.0, 2.0], [1.0, 1.0, 2.0]], columns=["t", "wz", "wz"])
    with pytest.raises(InputError, match=r"run\.csv: column 'wz' appears more than once"):
        validate_log(df, SRC)


def test_wrong_types():
    with pytest.raises(InputError, match="expected a pandas DataFrame"):
        Log({"t": [0, 1]})
    with pytest.raises(InputError, match="expected a Testbed"):
        Log(cmg_frame(), testbed="cmg-yaw")


# ----------------------------------------------------------------------------
# files

HEADER = "t,wz,yaw,d1,d2,d3,d4\n"
ROW = "{t},0.1,0.2,0,0,0,0\n"


def csv_text(n: int = 5) -> str:
    return HEADER + "".join(ROW.format(t=0.05 * i) for i in range(n))


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (HEADER + "0,0,0,0,0,0,0\n0.05,,0,0,0,0,0\n", ["row 1 (line 3), column 'wz'", "empty"]),
        (HEADER + "0,0,0,0,0,0,0\n\n\n0.05,0,x1,0,0,0,0\n", ["row 1 (line 5), column 'yaw'"]),
        (HEADER + "0,0,0,0,0,0,0\n0.05,0,nan,0,0,0,0\n", ["row 1 (line 3)", "'nan'"]),
        (HEADER + "0,0,0,0,0,0,0\n0.05,0,0,0,0,0\n", ["row 1 (line 3), column 'd4'"]),
        (HEADER + "0,0,0,0,0,0,0\n0.05,0,inf,0,0,0,0\n", ["row 1 (line 3)", "'inf'"]),
        (HEADER + "0,0,0,0,0,0,0\n0.05,0,0,0,0,0,0,0\n", ["not a valid CSV log"]),
        (HEADER + "0.05,0,0,0,0,0,0\n0,0,0,0,0,0,0\n", ["row 1 (line 3), column 't'"]),
        ("t,wz,wz\n0,0,0\n1,0,0\n", ["line 1: column 'wz' appears more than once"]),
        ("", ["the log is empty"]),
        ("t,wz\n0,0\n", ["at least 2 rows"]),
    ],
    ids=[
        "empty-cell",
        "text-after-blank-lines",
        "nan-text",
        "short-row",
        "inf-text",
        "long-row",
        "time-backwards",
        "duplicate-header",
        "empty-file",
        "one-row",
    ],
)
def test_csv_errors_name_row_and_line(tmp_path, text, fragments):
    path = tmp_path / "run.csv"
    path.write_text(text)
    with pytest.raises(InputError) as e:
        read_log(path)
    assert message(e).startswith(f"{path}: ")
    for fragment in fragments:
        assert fragment in message(e)


def test_csv_missing_column_names_testbed(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text(csv_text().replace("d4", "d5"))
    with pytest.raises(InputError) as e:
        read_log(path, CMG_YAW)
    assert "missing column 'd4'" in message(e) and "kind = 'cmg', dof = 1" in message(e)


def test_csv_gap_is_a_segment(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text(HEADER + "0,0,0,0,0,0,0\n0.05,0,0,0,0,0,0\n0.5,0,0,0,0,0,0\n0.55,0,0,0,0,0,0\n")
    assert read_log(path, CMG_YAW).segments == ((0, 2), (2, 4))


def test_csv_reads_spaces_and_extra_columns(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("t, wz ,note,n\n0, 1.5 ,a,1\n0.05,2,b,\n")
    log = read_log(path)
    np.testing.assert_array_equal(log.column("wz"), [1.5, 2.0])
    assert list(log.data["note"]) == ["a", "b"]
    assert log.data["n"].iloc[0] == 1 and np.isnan(log.data["n"].iloc[1])


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(InputError, match=r"run\.txt: unknown log format '\.txt'"):
        read_log(tmp_path / "run.txt")
    with pytest.raises(InputError, match=r"run\.csv: no such log file"):
        read_log(tmp_path / "run.csv")
    with pytest.raises(InputError, match="unknown log format '.xlsx'"):
        write_log(cmg_frame(), tmp_path / "run.xlsx")
    bad = tmp_path / "bad.parquet"
    bad.write_text("not parquet")
    with pytest.raises(InputError, match=r"bad\.parquet: cannot read the parquet log"):
        read_log(bad)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
@pytest.mark.parametrize("make", [platform_frame, cmg_frame], ids=["platform", "cmg"])
def test_round_trip(tmp_path, suffix, make):
    testbed = PLATFORM if make is platform_frame else CMG_YAW
    log = Log(make(n=50), testbed=testbed)
    path = write_log(log, tmp_path / f"run{suffix}")
    back = read_log(path, testbed)
    # The CSV writer prints the shortest text that reads back to the same float,
    # and Parquet stores binary doubles: both round trips are exact.
    pd.testing.assert_frame_equal(back.data, log.data, check_exact=True)
    assert back.source == str(path) and back.testbed is testbed


def test_parquet_nan_names_row(tmp_path):
    path = tmp_path / "run.parquet"
    with_value(cmg_frame(), 2, "wz", np.nan).to_parquet(path)
    with pytest.raises(InputError, match=r"run\.parquet: row 2, column 'wz'"):
        read_log(path)


def test_write_log_validates_and_leaves_no_file(tmp_path):
    df = cmg_frame()
    df.loc[4, "t"] = 0.0
    path = tmp_path / "run.csv"
    with pytest.raises(InputError, match=r"run\.csv: row 4, column 't'"):
        write_log(df, path)
    assert list(tmp_path.iterdir()) == []
    write_log(cmg_frame(), path)
    assert read_log(path, CMG_YAW).n == 20


def test_72000_rows_written_and_read_back_exactly(tmp_path):
    # a 72,000-row log (1 h at 20 Hz) round-trips exactly through CSV and Parquet; how fast
    # is a benchmark's question (docs/benchmarks.md), not a test's: no timing assertion
    log = Log(platform_frame(n=72_000).drop(columns="comment"), testbed=PLATFORM)
    for suffix in (".csv", ".parquet"):
        path = write_log(log, tmp_path / f"run{suffix}")
        back = read_log(path, PLATFORM)
        pd.testing.assert_frame_equal(back.data, log.data, check_exact=True)
