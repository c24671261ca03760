"""A log's samples checked against FORMATS.md ("Log (CSV or Parquet)") and normalised.

Validation never fills or drops anything: a missing column, an empty or non-numeric
cell, a non-finite or overflow-sized value (magnitude above :data:`OVERFLOW_LIMIT`, the
same rule on every column), time that does not increase, a log that is all gaps, a
median interval far from ``1 / sensors.rate`` or a non-unit quaternion raises
:class:`~airbearing.errors.InputError` (:class:`BadCellsError` for rows no tool can use)
naming the source, the row (0-based data row; CSV messages add the line of the file) and
the column, with the likely fix where there is one (two runs joined, a unit of time, a
scaled quaternion). Gaps, jitter and irregular intervals are not errors (the sampling
rules of :mod:`airbearing.io.log`). The front doors are :func:`validate_log` and
:class:`~airbearing.io.log.Log`; the readers and writers of :mod:`airbearing.io.log` call
:func:`validated`.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd

from airbearing.errors import InputError
from airbearing.io.columns import (
    _QUATERNION,
    COLUMN_GROUPS,
    GAP_FACTORS,
    LOG_COLUMNS,
    MIN_SEGMENT_ROWS,
    OVERFLOW_LIMIT,
    QUATERNION_NORM_TOL,
    RATE_MISMATCH_FACTOR,
    REQUIRED_COLUMNS,
    WHEEL_COMMAND_COLUMNS,
    WHEEL_SPEED_COLUMNS,
    bad_mask,
    row_ranges,
    segments_of,
    wheel_columns,
)
from airbearing.io.log_yaw import unwrap_wrapped_yaw
from airbearing.io.testbed import Testbed

__all__ = [
    "MEMORY_SOURCE",
    "BadCellsError",
    "column_list",
    "numeric_column",
    "quaternion_norm_hint",
    "restarts_at",
    "validate_log",
    "validated",
]

_MIN_ROWS = 2
#: The source of a log made in memory (not read from a file), in messages.
MEMORY_SOURCE = "<memory>"


def _check_wheel_columns(data: pd.DataFrame, src: str, testbed: Testbed | None) -> None:
    """``ws``/``wc`` columns against the testbed's wheel count (FORMATS.md: one per row of
    ``wheels.axes``); without a testbed, each family must run 1, 2, .. without a hole."""
    present = set(data.columns)
    n = None if testbed is None else (0 if testbed.wheels is None else testbed.wheels.n)
    for family, what in ((WHEEL_SPEED_COLUMNS, "speeds"), (WHEEL_COMMAND_COLUMNS, "commands")):
        have = [c for c in family if c in present]
        if not have:
            continue
        if n is not None:
            extra = [c for c in have if int(c[2:]) > n]
            if extra:
                if n == 0:
                    expected = "no wheel columns (the testbed has no [wheels])"
                else:
                    ws, wc = wheel_columns(n)
                    expected = (
                        f"{ws[0]} .. {ws[-1]} and {wc[0]} .. {wc[-1]} (its {n} wheel(s), one "
                        "per row of wheels.axes)"
                    )
                raise InputError(
                    f"{src}: column {extra[0]!r}: testbed {testbed.name!r} has {n} reaction "
                    f"wheel(s), so a log has {expected}; got wheel {what} {column_list(have)}"
                )
        k = n if n else int(have[-1][2:])
        missing = [c for c in family[:k] if c not in present]
        if missing:
            raise InputError(
                f"{src}: missing column {missing[0]!r}: the wheel {what} {family[0]} .. "
                f"{family[k - 1]} come together (all or none), but only {column_list(have)} given"
            )


def _at(row: int, lines: Sequence[int] | None) -> str:
    """'row N' (0-based data row, header not counted), with the file line for CSV."""
    if lines is None:
        return f"row {row}"
    return f"row {row} (line {lines[row]})"


def _describe(value: object) -> str:
    if isinstance(value, str):
        return "an empty cell" if value.strip() == "" else repr(value)
    if value is None or value is pd.NA:
        return "a missing cell"
    if isinstance(value, float) and np.isnan(value):
        return "NaN (a missing or 'nan' cell)"
    return repr(value)


def _as_float(series: pd.Series, name: str, src: str) -> np.ndarray:
    """A column as float64, NaN where a cell is not a number (booleans are not numbers)."""
    dtype = series.dtype
    if pd.api.types.is_bool_dtype(dtype):
        return np.full(len(series), np.nan)
    if pd.api.types.is_integer_dtype(dtype) or pd.api.types.is_float_dtype(dtype):
        return series.to_numpy(dtype=float, na_value=np.nan)
    if pd.api.types.is_numeric_dtype(dtype):  # complex and other numeric oddities
        raise InputError(
            f"{src}: column '{name}': expected real numbers, got values of type {dtype}"
        )
    cells = series.map(lambda v: v.strip() if isinstance(v, str) else v)
    is_bool = cells.map(lambda v: isinstance(v, bool | np.bool_)).to_numpy(dtype=bool)
    values = np.array(
        pd.to_numeric(cells, errors="coerce").to_numpy(dtype=float, na_value=np.nan), dtype=float
    )
    values[is_bool] = np.nan
    return values


class BadCellsError(InputError):
    """Rows no tool can use: cells that are not numbers, not finite or overflow-sized
    (:data:`OVERFLOW_LIMIT`), time that does not increase, or a non-unit quaternion.

    Attributes
    ----------
    bad : dict of str to list of int
        For each column with bad cells, all its bad rows (0-based data rows).
    """

    def __init__(self, message: str, bad: dict[str, list[int]]) -> None:
        super().__init__(message)
        self.bad = bad

    @property
    def rows(self) -> list[int]:
        """Every row with a bad cell, sorted."""
        return sorted({r for rows in self.bad.values() for r in rows})


def numeric_column(
    series: pd.Series, name: str, src: str, lines: Sequence[int] | None
) -> np.ndarray:
    """A column as float64; a cell that is not a finite number (:func:`bad_mask`) is an error.

    Parameters
    ----------
    series : pandas.Series
        The column's cells.
    name : str
        Its name, for the message.
    src : str
        Name of the origin, for the message.
    lines : sequence of int or None
        The file line of each data row (a CSV file), or None.

    Returns
    -------
    numpy.ndarray
        Shape (n,), float64 (the column's unit).

    Raises
    ------
    BadCellsError
        Naming the first bad row, and every bad row.
    """
    values = _as_float(series, name, src)
    bad = bad_mask(values)
    if bad.any():
        raise _bad_cell(series, name, int(np.argmax(bad)), src, lines, {name: bad})
    return values


def _bad_cell(
    series: pd.Series,
    name: str,
    i: int,
    src: str,
    lines: Sequence[int] | None,
    masks: dict[str, np.ndarray] | None = None,
) -> BadCellsError:
    bad = {c: [int(r) for r in np.flatnonzero(m)] for c, m in (masks or {name: None}).items()
           if m is not None}  # fmt: skip
    bad = bad or {name: [i]}
    value = series.iloc[i]
    try:
        big = np.isfinite(float(value)) and abs(float(value)) > OVERFLOW_LIMIT
    except (TypeError, ValueError):
        big = False
    got = f"{float(value):.6g}" if big else _describe(value)
    limit = (
        f" of magnitude at most {OVERFLOW_LIMIT:g} (larger values overflow float64 in the fits)"
        if big
        else ""
    )
    n = sum(len(r) for r in bad.values())
    more = ""
    if n > 1:
        more = f"; {n} such cells: " + "; ".join(
            f"column '{c}' rows {row_ranges(r)}" for c, r in bad.items()
        )
    dropout = not big and (got == "an empty cell" or got.startswith("NaN") or got == "'nan'")
    return BadCellsError(
        f"{src}: {_at(i, lines)}, column '{name}': expected a finite number{limit}, "
        f"got {got}{more}"
        + (
            "; if these are dropouts, remove those rows (the time across them is a gap) or "
            'import the raw file with missing = "gap" in its import map'
            if dropout
            else ""
        ),
        bad,
    )


def column_list(columns: Iterable[str]) -> str:
    """The names of ``columns`` joined by commas (for a message)."""
    return ", ".join(str(c) for c in columns)


def _check_required(df: pd.DataFrame, src: str, testbed: Testbed, columns: Sequence[str]) -> None:
    who = f"testbed {testbed.name!r} (kind = {testbed.kind!r}, dof = {testbed.body.dof})"
    for column in REQUIRED_COLUMNS(testbed):
        if column in df.columns:
            continue
        if column == "yaw":
            if all(q in df.columns for q in _QUATERNION):
                continue
            raise InputError(
                f"{src}: missing column 'yaw' (rad; or the quaternion qw, qx, qy, qz), "
                f"needed by {who}; columns present: {column_list(columns)}"
            )
        raise InputError(
            f"{src}: missing column {column!r}, needed by {who}; "
            f"columns present: {column_list(columns)}"
        )


def validated(
    data: pd.DataFrame,
    src: str,
    testbed: Testbed | None,
    lines: Sequence[int] | None = None,
    *,
    fresh: bool = False,
    unwrap_yaw: bool = True,
) -> pd.DataFrame:
    """The checks of :func:`validate_log`, for the readers and writers of logs.

    Parameters
    ----------
    data : pandas.DataFrame
        One row per sample (:func:`validate_log`).
    src : str
        Name of the origin, used in error messages.
    testbed : Testbed or None
        As :func:`validate_log`.
    lines : sequence of int, optional
        The file line of each data row (a CSV file), named in the messages.
    fresh : bool
        ``data`` was just read from a file and nobody else holds it, so it is normalised
        in place instead of copied.
    unwrap_yaw : bool
        A yaw written wrapped is unwrapped (:func:`~airbearing.io.log_yaw.unwrap_wrapped_yaw`;
        not when writing: a file holds what it was given).

    Returns
    -------
    pandas.DataFrame
        As :func:`validate_log`.
    """
    if not isinstance(data, pd.DataFrame):
        raise InputError(f"{src}: expected a pandas DataFrame, got {type(data).__name__}")
    if testbed is not None and not isinstance(testbed, Testbed):
        raise InputError(f"{src}: expected a Testbed or None, got {type(testbed).__name__}")
    columns = list(data.columns)
    duplicated = data.columns[data.columns.duplicated()]
    if len(duplicated):
        raise InputError(f"{src}: column {duplicated[0]!r} appears more than once")
    if "t" not in data.columns:
        raise InputError(
            f"{src}: missing column 't' (time, s), which every log needs; "
            f"columns present: {column_list(columns)}"
        )
    if len(data) < _MIN_ROWS:
        raise InputError(f"{src}: a log needs at least {_MIN_ROWS} rows, got {len(data)}")
    if testbed is not None:
        _check_required(data, src, testbed, columns)
    _check_wheel_columns(data, src, testbed)
    for group in COLUMN_GROUPS:
        have = [c for c in group if c in data.columns]
        if have and len(have) != len(group):
            missing = [c for c in group if c not in data.columns]
            raise InputError(
                f"{src}: missing column(s) {column_list(missing)}: the columns "
                f"{column_list(group)} come together (all or none), but only "
                f"{column_list(have)} given"
            )

    if fresh and isinstance(data.index, pd.RangeIndex) and data.index.start == 0:
        out = data
    else:
        out = data.reset_index(drop=True).copy()
    # Non-numeric and non-finite cells: report the earliest row over all known columns.
    first_bad: tuple[int, str, pd.Series] | None = None
    masks: dict[str, np.ndarray] = {}
    for name in [c for c in columns if c in LOG_COLUMNS]:
        cells = out[name]
        values = _as_float(cells, name, src)
        bad = bad_mask(values)
        if bad.any():
            masks[name] = bad
            if first_bad is None or int(np.argmax(bad)) < first_bad[0]:
                first_bad = (int(np.argmax(bad)), name, cells.copy())
        if cells.dtype != np.float64:  # a float64 column already holds these values
            out[name] = values
    if first_bad is not None:
        row, name, cells = first_bad
        raise _bad_cell(cells, name, row, src, lines, masks)

    t = out["t"].to_numpy()
    dt = np.diff(t)
    not_increasing = ~(dt > 0.0)
    if not_increasing.any():
        i = int(np.argmax(not_increasing)) + 1  # 0-based index of the offending row
        rows = [int(r) + 1 for r in np.flatnonzero(not_increasing)]
        raise BadCellsError(
            f"{src}: {_at(i, lines)}, column 't': time must be strictly increasing, "
            f"but t = {float(t[i])!r} s follows t = {float(t[i - 1])!r} s of row {i - 1}"
            + (f"; {len(rows)} such rows: {row_ranges(rows)}" if len(rows) > 1 else "")
            + _restart_hint(t, rows),
            {"t": rows},
        )
    if unwrap_yaw:
        unwrap_wrapped_yaw(out, testbed)
    if testbed is not None:
        period = testbed.sensors.dt
        segments = segments_of(t, period)
        if max(stop - start for start, stop in segments) < MIN_SEGMENT_ROWS:
            raise InputError(
                f"{src}: the log is all gaps: every one of its {len(t)} rows is more than "
                f"{GAP_FACTORS[1]:g} / sensors.rate = {GAP_FACTORS[1] * period:.6g} s from its "
                f"neighbours (testbed {testbed.name!r}, sensors.rate = {testbed.sensors.rate:g} "
                f"Hz), so no segment has {MIN_SEGMENT_ROWS} samples; expected samples every "
                f"{period:.6g} s (median interval {float(np.median(dt)):.6g} s: "
                f"{_unit_hint(float(np.median(dt)), period)})"
            )
        _check_rate(t, src, testbed)
    if all(q in out.columns for q in _QUATERNION):
        qw, qx, qy, qz = (out[c].to_numpy() for c in _QUATERNION)
        norm = np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        off = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
        if off.any():
            i = int(np.argmax(off))
            rows = [int(r) for r in np.flatnonzero(off)]
            raise BadCellsError(
                f"{src}: {_at(i, lines)}, columns qw, qx, qy, qz: expected a unit "
                f"quaternion (norm within {QUATERNION_NORM_TOL:g} of 1), got norm {norm[i]:.9g}"
                + (f"; {len(rows)} such rows: {row_ranges(rows)}" if len(rows) > 1 else "")
                + quaternion_norm_hint(norm),
                {"qw, qx, qy, qz": rows},
            )
    return out


def quaternion_norm_hint(norm: np.ndarray) -> str:
    """The fix of a quaternion whose norm is off 1, in words: a whole log at one norm is a
    scaled export; a few rows are cells that are not a quaternion."""
    good = norm[np.isfinite(norm)]
    if good.size and float(np.ptp(good)) <= QUATERNION_NORM_TOL * float(np.mean(good)):
        x = float(np.mean(good))
        return (
            f"; every row has norm {x:.6g}: a quaternion exported scaled, or another quantity "
            f"(divide qw, qx, qy, qz by {x:.6g} if they are a scaled attitude; the tools "
            f"renormalise only within {QUATERNION_NORM_TOL:g} of 1)"
        )
    return "; fix those rows (a unit quaternion qw, qx, qy, qz, scalar first) or remove them"


def restarts_at(t: np.ndarray, i: int, start: int) -> bool:
    """Whether the step back of time at row ``i`` starts a new run (two runs joined).

    A second run's clock may restart at 0 or at any earlier value (a recorder that
    restarts its clock at an arbitrary time): the step back counts as a restart when the
    run before it has at least 2 rows and time goes back past at least two of its samples
    (``t[i] <= t[i - 2]``) and stays back at the next row (``t[i + 1] <= t[i - 1]``). A
    repeated time, two swapped rows or one misplaced row is not a restart: it is undone
    within a row.

    Parameters
    ----------
    t : numpy.ndarray
        s, shape (n,).
    i : int
        A row where time does not increase (``t[i] <= t[i - 1]``).
    start : int
        First row of the run ``i`` would end.
    """
    if i - start < 2 or not t[i] < t[i - 1]:
        return False
    if not t[i] <= t[i - 2]:
        return False
    return i + 1 >= len(t) or bool(t[i + 1] <= t[i - 1])


def _restart_hint(t: np.ndarray, rows: Sequence[int]) -> str:
    """When time steps back to an earlier value and runs on from there (two runs joined,
    :func:`restarts_at`), say where to split; ``""`` for a repeated or out-of-order time."""
    starts = [0]
    for i in rows:
        if not restarts_at(t, i, starts[-1]):
            return ""
        starts.append(i)
    if len(t) - starts[-1] < 2:
        return ""
    at = ", ".join(str(i) for i in starts[1:])
    n = len(starts)
    return (
        f": time restarts, {'two' if n == 2 else n} runs in one file: split at "
        f'row{"s" if n > 2 else ""} {at} (or import the raw file with restart = "split" in '
        "its import map: one log per run)"
    )


def _check_rate(t: np.ndarray, src: str, testbed: Testbed) -> None:
    """The log's median interval against ``1 / sensors.rate``: beyond a factor
    :data:`RATE_MISMATCH_FACTOR` either way is an error.

    Jitter moves the median interval of a log sampled at the testbed's rate by a few
    percent at most; the nearest rates a lab mixes up differ by 2x (10 and 20 Hz) or
    more, and a time column in the wrong unit by 1000x. A median interval beyond 1.5
    periods makes most intervals gaps (the gap rule's own factor); below 1 / 1.5 of a
    period most samples are far closer than the testbed's sensors deliver. Either way
    the gaps, the noise per sample and every discrete-time model would be wrong.
    """
    dt = np.diff(t)
    if dt.size == 0:
        return
    median = float(np.median(dt))
    period = testbed.sensors.dt
    ratio = median / period
    if 1.0 / RATE_MISMATCH_FACTOR <= ratio <= RATE_MISMATCH_FACTOR:
        return
    raise InputError(
        f"{src}: column 't': median sample interval {median:.6g} s ({1.0 / median:.6g} Hz) "
        f"is {ratio:.3g} x the testbed's 1 / sensors.rate = {period:.6g} s (testbed "
        f"{testbed.name!r}, sensors.rate = {testbed.sensors.rate:g} Hz); expected within a "
        f"factor {RATE_MISMATCH_FACTOR:g} either way ({_unit_hint(median, period)})"
    )


def _unit_hint(median: float, period: float) -> str:
    """The likely cause of a median interval far from the period, in words."""
    ratio = median / period
    for factor, hint in (
        (1e3, 'looks like ms: use airbearing log import with [units] t = "ms" in the map'),
        (1e6, 'looks like us: use airbearing log import with [units] t = "us" in the map'),
        (1e-3, 'looks like s read as ms: [units] t = "s" in the import map'),
        (1e-6, 'looks like s read as us: [units] t = "s" in the import map'),
    ):
        if 1.0 / RATE_MISMATCH_FACTOR <= ratio / factor <= RATE_MISMATCH_FACTOR:
            return f"t {hint}"
    return "t in another unit, or another testbed's log (its sensors.rate)?"


def validate_log(
    data: pd.DataFrame, source: str = MEMORY_SOURCE, testbed: Testbed | None = None
) -> pd.DataFrame:
    """Check a table of samples against FORMATS.md and return it normalised.

    Parameters
    ----------
    data : pandas.DataFrame
        One row per sample. Columns of FORMATS.md in SI units (t in s, angles
        in rad, rates in rad/s, sliders in m, dipoles in A m^2, fields in T);
        other columns are kept and ignored.
    source : str
        Name of the origin, used in error messages.
    testbed : Testbed or None
        If given, the columns its kind, dof, ``[masses]`` and
        ``sensors.gyro`` need are required (:func:`REQUIRED_COLUMNS`), and at
        least one segment (intervals up to ``1.5 / sensors.rate``) must have
        2 samples. Gaps and jitter are not errors (see the module notes).

    Returns
    -------
    pandas.DataFrame
        A copy with a fresh RangeIndex and every FORMATS.md column as float64; a ``yaw``
        written wrapped is unwrapped, its rows in ``.attrs["yaw_unwrapped_rows"]``
        (:mod:`airbearing.io.log_yaw`).

    Raises
    ------
    InputError
        On a missing column, fewer than 2 rows, an empty, non-numeric or
        non-finite cell, time not strictly increasing, a log that is all gaps,
        an incomplete column group (``mx, my, mz``; ``bx, by, bz``;
        ``dd1 .. dd4``; and likewise the quaternion, sliders and gimbals), or
        a quaternion whose norm is off 1 by more than 1e-3. The message names
        ``source``, the row (0-based data row) and the column.
    """
    return validated(data, str(source), testbed)
