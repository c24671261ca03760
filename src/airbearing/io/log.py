"""Logs (FORMATS.md, "Log (CSV or Parquet)"): read, validate, write.

A :class:`Log` holds one run's samples as a validated :class:`pandas.DataFrame`:
one row per sample, the columns of FORMATS.md (SI units) as float64, and any
other columns kept untouched. Validation never fills or drops anything: a
missing column, an empty or non-numeric cell, a non-finite or overflow-sized value
(magnitude above :data:`OVERFLOW_LIMIT`, the same rule on every column), time that
does not increase, a log that is all gaps or a non-unit quaternion raises
:class:`~airbearing.errors.InputError` naming the file, the row and the column.

Rows are 0-based data-row indices (the header is not counted), the same in a raw
file, its imported log and every report; CSV messages add the line of the file.

A ``yaw`` written wrapped (within one turn, jumping by about 2 pi between samples) is
unwrapped on read and said (:func:`_unwrap_yaw`, ``data.attrs[YAW_UNWRAPPED]``): the
built-in CMG simulation and many loggers write it so, and no fit can use it wrapped.

Sampling (FORMATS.md, "Real logs are not perfect"), with ``T = 1 / sensors.rate``:

- an interval within ``[0.5 T, 1.5 T]`` is normal jitter: used with its logged times;
- an interval longer than ``1.5 T`` is a **gap**: it splits the log into segments
  (:func:`segments_of`); never an error;
- an interval shorter than ``0.5 T`` is **irregular** (a duplicated or late
  sample, a logger hiccup): used with its logged time like any other, not an
  error, and reported by ``airbearing log check``;
- a log in which no segment has at least 2 samples ("all gaps") is an error:
  nothing can be integrated, differentiated or fitted on it.

Files are read and written with pyarrow (``pyarrow.csv``, ``pyarrow.parquet``);
a CSV that the fast reader refuses is read again cell by cell as text so that the
error names the row, the line and the column.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.io.columns import (  # noqa: F401 (re-exported: the log module's names)
    _DIPOLES,
    _FIELDS,
    _GIMBAL_RATES,
    _GIMBALS,
    _MAX_WHEELS,
    _QUATERNION,
    _RATES,
    _SLIDERS,
    COLUMN_GROUPS,
    GAP_FACTORS,
    LOG_COLUMNS,
    MIN_SEGMENT_ROWS,
    OVERFLOW_LIMIT,
    QUATERNION_NORM_TOL,
    RATE_COLUMNS,
    RATE_MISMATCH_FACTOR,
    REQUIRED_COLUMNS,
    WHEEL_COMMAND_COLUMNS,
    WHEEL_SPEED_COLUMNS,
    bad_mask,
    row_ranges,
    segments_of,
    time_text,
    wheel_columns,
)
from airbearing.io.import_map import unwrap
from airbearing.io.quality import LogQuality, assess
from airbearing.io.testbed import Testbed, _atomic_write_bytes

__all__ = [
    "BadCellsError",
    "COLUMN_GROUPS",
    "OVERFLOW_LIMIT",
    "GAP_FACTORS",
    "RATE_MISMATCH_FACTOR",
    "LOG_COLUMNS",
    "MIN_SEGMENT_ROWS",
    "QUATERNION_NORM_TOL",
    "RATE_COLUMNS",
    "REQUIRED_COLUMNS",
    "WHEEL_COMMAND_COLUMNS",
    "WHEEL_SPEED_COLUMNS",
    "YAW_UNWRAPPED",
    "Log",
    "read_log",
    "time_text",
    "quaternion_norm_hint",
    "restarts_at",
    "segments_of",
    "yaw_unwrapped_words",
    "validate_log",
    "wheel_columns",
    "wheel_saturation",
    "write_log",
]

_MIN_ROWS = 2
_MEMORY = "<memory>"


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
                    f"wheel(s), so a log has {expected}; got wheel {what} {_present(have)}"
                )
        k = n if n else int(have[-1][2:])
        missing = [c for c in family[:k] if c not in present]
        if missing:
            raise InputError(
                f"{src}: missing column {missing[0]!r}: the wheel {what} {family[0]} .. "
                f"{family[k - 1]} come together (all or none), but only {_present(have)} given"
            )


def wheel_saturation(log: Log) -> tuple[dict, ...]:
    """Logged wheel commands beyond the wheels' limit: reported, never clipped.

    A torque command (``wheels.command = "torque"``) beyond ``max_torque``, or a speed
    command beyond ``max_speed``, is what the controller asked for; the wheel gave the
    limit (the Model clips it the same way).

    Parameters
    ----------
    log : Log
        A log read with its testbed.

    Returns
    -------
    tuple of dict
        One per saturated column: ``column``, ``rows`` (0-based data rows), ``limit``
        (N m or rad/s), ``largest`` (the largest logged magnitude) and ``reason``; empty
        without wheels or wheel commands.
    """
    tb = log.testbed
    if tb is None or tb.wheels is None:
        return ()
    wheels = tb.wheels
    torque = wheels.command == "torque"
    limit = wheels.max_torque if torque else wheels.max_speed
    unit, key = ("N m", "max_torque") if torque else ("rad/s", "max_speed")
    out = []
    for column in wheel_columns(wheels.n)[1]:
        if column not in log.data.columns:
            continue
        values = log.column(column)
        beyond = np.flatnonzero(np.abs(values) > limit)
        if beyond.size:
            rows = [int(r) for r in beyond]
            largest = float(np.max(np.abs(values[beyond])))
            out.append(
                {
                    "column": column,
                    "rows": rows,
                    "limit": limit,
                    "largest": largest,
                    "reason": (
                        f"{column} beyond wheels.{key} = {limit:g} {unit} in {len(rows)} row(s) "
                        f"({row_ranges(rows)}; largest {largest:.4g} {unit}): saturated, the "
                        "wheel gave the limit (the log is kept as is)"
                    ),
                }
            )
    return tuple(out)


# ----------------------------------------------------------------------------
# validation


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


def _numeric(series: pd.Series, name: str, src: str, lines: Sequence[int] | None) -> np.ndarray:
    """A column as float64; a cell that is not a finite number (:func:`bad_mask`) is an error."""
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


def _present(columns: Iterable[str]) -> str:
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
                f"needed by {who}; columns present: {_present(columns)}"
            )
        raise InputError(
            f"{src}: missing column {column!r}, needed by {who}; "
            f"columns present: {_present(columns)}"
        )


def _validate(
    data: pd.DataFrame,
    src: str,
    testbed: Testbed | None,
    lines: Sequence[int] | None = None,
    *,
    fresh: bool = False,
    unwrap_yaw: bool = True,
) -> pd.DataFrame:
    """The checks of :func:`validate_log`; ``fresh``: ``data`` was just read from a file
    and nobody else holds it, so it is normalised in place instead of copied;
    ``unwrap_yaw``: a yaw written wrapped is unwrapped (:func:`_unwrap_yaw`; not when
    writing: a file holds what it was given)."""
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
            f"columns present: {_present(columns)}"
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
                f"{src}: missing column(s) {_present(missing)}: the columns "
                f"{_present(group)} come together (all or none), but only "
                f"{_present(have)} given"
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
        _unwrap_yaw(out, testbed)
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


#: rad: a step of the logged yaw between two samples larger than this, which is within
#: :data:`_WRAP_SLACK` of a whole turn, in a yaw that stays within one turn, is the angle
#: written wrapped (to [-pi, pi) or [0, 2 pi)), not motion: no air bearing turns by pi within
#: one sample.
_WRAP_STEP = math.pi
_WRAP_SLACK = math.pi / 2
#: rad: a yaw is judged only if its median step between samples is below this (a rig
#: turning 0.4 rad per sample, 4 rad/s at 10 Hz, is; white noise of 1 rad is not).
_SMOOTH_STEP = math.pi / 4
#: Key of ``Log.data.attrs``: the rows where a yaw written wrapped was unwrapped on read.
YAW_UNWRAPPED = "yaw_unwrapped_rows"


def _unwrap_yaw(out: pd.DataFrame, testbed: Testbed | None) -> None:
    """A logged ``yaw`` written wrapped is unwrapped on read, and said.

    The signature of a wrapped yaw: it stays within one turn (its range is at most 2 pi),
    moves smoothly (median step below :data:`_SMOOTH_STEP`) and jumps by about a whole turn
    (more than pi, within pi/2 of 2 pi k) between two samples of a segment. Such a yaw is
    unwrapped as the import map does (:func:`airbearing.io.import_map.unwrap`: each segment
    on its own, an isolated jump keeping the branch), and the rows where its branch changes
    are kept in ``out.attrs[YAW_UNWRAPPED]`` for ``log check`` and the tools to say. A
    glitch (a frame exported as 0) on a spinning yaw is not one: the yaw spans more than a
    turn.
    """
    if "yaw" not in out.columns or len(out) < 3:
        return
    yaw = out["yaw"].to_numpy()
    if not float(np.ptp(yaw)) <= 2 * math.pi + 1e-9:
        return
    t = out["t"].to_numpy()
    period = testbed.sensors.dt if testbed is not None else float(np.median(np.diff(t)))
    step = np.diff(yaw)
    wrapped = np.abs(np.mod(step + math.pi, 2 * math.pi) - math.pi)
    inside = np.diff(t) <= GAP_FACTORS[1] * period
    jump = (np.abs(step) > _WRAP_STEP) & (wrapped < _WRAP_SLACK) & inside
    if not jump.any() or not np.median(wrapped[inside]) < _SMOOTH_STEP:
        return

    new = unwrap(yaw, t)
    turns = np.round((new - yaw) / (2 * math.pi))
    rows = [int(r) for r in np.flatnonzero(np.diff(turns) != 0) + 1]
    if not rows:
        return
    out["yaw"] = new
    out.attrs[YAW_UNWRAPPED] = rows


def yaw_unwrapped_words(rows: Sequence[int]) -> str:
    """The sentence that says a yaw was unwrapped on read (``""`` for no rows)."""
    if not rows:
        return ""
    shown = row_ranges(list(rows)[:10]) + (" ..." if len(rows) > 10 else "")
    return (
        f"yaw written wrapped (to one turn): unwrapped on read, {len(rows)} jump(s) of 2 pi "
        f"removed at row(s) {shown}; the file is unchanged (import raw files with 'airbearing "
        "log import', which writes the yaw unwrapped)"
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
    data: pd.DataFrame, source: str = _MEMORY, testbed: Testbed | None = None
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
        (module doc).

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
    return _validate(data, str(source), testbed)


# ----------------------------------------------------------------------------
# the Log


class Log:
    """One run's samples, validated against FORMATS.md.

    Parameters
    ----------
    data : pandas.DataFrame
        The samples; validated by :func:`validate_log` and stored as a
        normalised copy.
    source : str
        Where the samples came from (a path or ``"<memory>"``).
    testbed : Testbed or None
        The testbed the log belongs to; enables its column and sampling checks.

    Attributes
    ----------
    data : pandas.DataFrame
    source : str
    testbed : Testbed or None

    Notes
    -----
    The array accessors (:meth:`rates`, :meth:`quaternions`, ...) return
    copies in SI units, or None when the log lacks those columns.

    Examples
    --------
    A simulated 2 s slew of the yaw CMG testbed, sampled at 20 Hz:

    >>> import airbearing as ab
    >>> log = ab.slew(ab.load_testbed("cmg-yaw"), angle_deg=30.0, duration=2.0).log
    >>> log.n, round(log.period, 3), log.segments  # samples, s, row ranges
    (40, 0.05, ((0, 40),))
    >>> log.rates().shape, log.gimbals().shape, log.has("wz", "d1")  # rad/s, rad
    ((40, 1), (40, 4), True)
    >>> log.quaternions() is None  # a yaw-only log has no quaternion columns
    True
    """

    def __init__(
        self, data: pd.DataFrame, source: str = _MEMORY, testbed: Testbed | None = None
    ) -> None:
        self.source = str(source)
        self.testbed = testbed
        self.data = _validate(data, self.source, testbed)

    @classmethod
    def _from_validated(cls, data: pd.DataFrame, source: str, testbed: Testbed | None) -> Log:
        log = cls.__new__(cls)
        log.source, log.testbed, log.data = source, testbed, data
        return log

    # -- sampling and quality (FORMATS.md, "Real logs are not perfect")

    @property
    def period(self) -> float:
        """Nominal sample interval, s: ``1 / sensors.rate`` (without a testbed: the median)."""
        return self.testbed.sensors.dt if self.testbed is not None else self.dt

    @property
    def segments(self) -> tuple[tuple[int, int], ...]:
        """``(start, stop)`` row ranges between gaps (0-based, stop exclusive).

        A gap is an interval longer than 1.5 periods (:attr:`period`). Nothing
        may be integrated, differentiated or fitted across a gap.
        """
        cached = self.__dict__.get("_segments")
        if cached is None:
            cached = segments_of(self.data["t"].to_numpy(dtype=float), self.period)
            self.__dict__["_segments"] = cached
        return cached

    @property
    def quality(self) -> LogQuality:
        """Segments, jitter and outliers of this log (:func:`airbearing.io.quality.assess`).

        Computed once and cached. Uses the testbed (its sample rate says what a gap
        is, its sensors which columns are measurements and the noise floors);
        without one, the median interval and no floors.
        """
        cached = self.__dict__.get("_quality")
        if cached is None:
            cached = assess(self, self.testbed)
            self.__dict__["_quality"] = cached
        return cached

    def usable_mask(self) -> np.ndarray:
        """Rows every fit may use: False at :attr:`quality` outlier rows.

        Returns
        -------
        numpy.ndarray
            Shape (n,), bool.
        """
        mask = np.ones(self.n, dtype=bool)
        mask[list(self.quality.outlier_rows)] = False
        return mask

    def __repr__(self) -> str:
        tb = "None" if self.testbed is None else repr(self.testbed.name)
        return (
            f"Log(source={self.source!r}, n={self.n}, "
            f"t=[{self.t[0]:g}, {self.t[-1]:g}] s, testbed={tb}, "
            f"columns=[{_present(self.data.columns)}])"
        )

    def __len__(self) -> int:
        return self.n

    @property
    def n(self) -> int:
        """Number of samples (rows)."""
        return len(self.data)

    @property
    def t(self) -> np.ndarray:
        """Sample times, s, shape (n,)."""
        return self.data["t"].to_numpy(dtype=float, copy=True)

    @property
    def dt(self) -> float:
        """Median sample interval, s."""
        return float(np.median(np.diff(self.data["t"].to_numpy(dtype=float))))

    def has(self, *names: str) -> bool:
        """Whether every named column is present.

        Parameters
        ----------
        *names : str
            Column names (FORMATS.md).

        Returns
        -------
        bool
        """
        return all(name in self.data.columns for name in names)

    def column(self, name: str) -> np.ndarray:
        """One column as a float array.

        Parameters
        ----------
        name : str
            The column (FORMATS.md or an extra column); its unit is the file's.

        Returns
        -------
        numpy.ndarray
            Shape (n,), a copy.

        Raises
        ------
        InputError
            If the column is absent or (for an extra column) not numeric.
        """
        if name not in self.data.columns:
            raise InputError(
                f"{self.source}: no column {name!r}; columns present: {_present(self.data.columns)}"
            )
        return _numeric(self.data[name], name, self.source, None).copy()

    def columns(self, names: Sequence[str]) -> np.ndarray:
        """Several columns as a float array.

        Parameters
        ----------
        names : sequence of str
            The columns, in the order wanted.

        Returns
        -------
        numpy.ndarray
            Shape (n, len(names)), a copy.

        Raises
        ------
        InputError
            If a column is absent or not numeric.
        """
        out = np.empty((self.n, len(names)))
        for i, name in enumerate(names):
            if name in LOG_COLUMNS and name in self.data.columns and self.data[name].dtype == float:
                out[:, i] = self.data[name].to_numpy()  # validated: finite float64
            else:
                out[:, i] = self.column(name)
        return out

    def _optional(self, names: Sequence[str]) -> np.ndarray | None:
        return self.columns(names) if self.has(*names) else None

    def rates(self) -> np.ndarray | None:
        """Measured angular rate, rad/s, body axes.

        Returns
        -------
        numpy.ndarray or None
            Shape (n, 3) ``wx, wy, wz`` for a dof-3 testbed (or, without a
            testbed, when all three are present); shape (n, 1) ``wz`` for a
            dof-1 testbed (or when only ``wz`` is present); None if absent,
            and None when the testbed has no rate sensor (``sensors.gyro =
            false``: rate columns, if any, are not measurements and are ignored).
        """
        if self.testbed is not None and not self.testbed.sensors.gyro:
            return None
        dof = None if self.testbed is None else self.testbed.body.dof
        if dof != 1 and self.has(*_RATES):
            return self.columns(_RATES)
        if dof != 3 and self.has("wz"):
            return self.columns(["wz"])
        return None

    def quaternions(self) -> np.ndarray | None:
        """Attitude quaternion body -> lab, scalar first.

        Returns
        -------
        numpy.ndarray or None
            Shape (n, 4) ``qw, qx, qy, qz``; None if absent.
        """
        return self._optional(_QUATERNION)

    def yaw(self) -> np.ndarray | None:
        """Logged yaw (not derived from the quaternion).

        Returns
        -------
        numpy.ndarray or None
            rad, shape (n,); None if absent.
        """
        return self.column("yaw") if self.has("yaw") else None

    def yaw_ref(self) -> np.ndarray | None:
        """Commanded yaw.

        Returns
        -------
        numpy.ndarray or None
            rad, shape (n,); None if absent.
        """
        return self.column("yaw_ref") if self.has("yaw_ref") else None

    def sliders(self) -> np.ndarray | None:
        """Slider positions along their rails.

        Returns
        -------
        numpy.ndarray or None
            m, shape (n, 3); None if absent.
        """
        return self._optional(_SLIDERS)

    def dipoles(self) -> np.ndarray | None:
        """Commanded magnetorquer dipole, body axes.

        Returns
        -------
        numpy.ndarray or None
            A m^2, shape (n, 3); None if absent.
        """
        return self._optional(_DIPOLES)

    def fields(self) -> np.ndarray | None:
        """Logged magnetic field, body axes.

        Returns
        -------
        numpy.ndarray or None
            T, shape (n, 3); None if absent.
        """
        return self._optional(_FIELDS)

    def gimbals(self) -> np.ndarray | None:
        """Measured gimbal angles.

        Returns
        -------
        numpy.ndarray or None
            rad, shape (n, 4); None if absent.
        """
        return self._optional(_GIMBALS)

    def gimbal_rates(self) -> np.ndarray | None:
        """Commanded gimbal rates.

        Returns
        -------
        numpy.ndarray or None
            rad/s, shape (n, 4); None if absent.
        """
        return self._optional(_GIMBAL_RATES)

    def _wheel_family(self, family: tuple[str, ...]) -> np.ndarray | None:
        if self.testbed is not None:
            n = 0 if self.testbed.wheels is None else self.testbed.wheels.n
        else:
            n = sum(1 for c in family if c in self.data.columns)
        return self._optional(family[:n]) if n else None

    def wheel_speeds(self) -> np.ndarray | None:
        """Measured wheel speeds ``ws1 .. wsn`` (relative to the body).

        Returns
        -------
        numpy.ndarray or None
            rad/s, shape (n, k) for k wheels; None if absent.
        """
        return self._wheel_family(WHEEL_SPEED_COLUMNS)

    def wheel_commands(self) -> np.ndarray | None:
        """Wheel commands ``wc1 .. wcn``.

        Returns
        -------
        numpy.ndarray or None
            N m (rad/s for ``wheels.command = "speed"``), shape (n, k) for k wheels; None
            if absent.
        """
        return self._wheel_family(WHEEL_COMMAND_COLUMNS)


# ----------------------------------------------------------------------------
# files

_CSV_SUFFIXES = (".csv",)
_PARQUET_SUFFIXES = (".parquet", ".pq")


def _format(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix in _CSV_SUFFIXES:
        return "csv"
    if suffix in _PARQUET_SUFFIXES:
        return "parquet"
    raise InputError(
        f"{path}: unknown log format {path.suffix!r}; expected one of "
        f"{', '.join(_CSV_SUFFIXES + _PARQUET_SUFFIXES)}"
    )


def _read_csv(path: Path, src: str) -> tuple[pd.DataFrame, list[int] | None]:
    try:
        # utf-8-sig: a byte-order mark (Excel's "CSV UTF-8") is not part of the first name
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a UTF-8 text file ({e})") from e
    raw_lines = text.split("\n")
    content = [i + 1 for i, line in enumerate(raw_lines) if line.strip()]
    if not content:
        raise InputError(f"{src}: the log is empty; expected a header row and data rows")
    _check_separator(raw_lines[content[0] - 1], src, content[0])
    header = next(csv.reader([raw_lines[content[0] - 1]]))
    names = [h.strip() for h in header]
    seen: set[str] = set()
    for name in names:
        if name in seen:
            raise InputError(f"{src}: line {content[0]}: column {name!r} appears more than once")
        seen.add(name)
    try:
        # Every cell as text: nothing is turned into NaN behind our back.
        df = pd.read_csv(io.StringIO(text), dtype=str, keep_default_na=False)
    except (pd.errors.ParserError, ValueError) as e:
        raise InputError(f"{src}: not a valid CSV log: {str(e).strip()}") from e
    df.columns = names
    lines = content[1:] if len(content) - 1 == len(df) else None
    for name in df.columns:
        if name not in LOG_COLUMNS:  # extra columns: numbers if they all parse, else text
            cells = df[name].str.strip()
            try:
                df[name] = pd.to_numeric(cells.replace("", np.nan))
            except (TypeError, ValueError):
                pass  # not numeric: kept as text, as FORMATS.md keeps unknown columns
    return df, lines


def _check_separator(header: str, src: str, line: int) -> None:
    """A log is comma separated (FORMATS.md): a header with tabs or semicolons and no
    comma is another separator, named instead of one long column name."""
    if "," in header:
        return
    for sep, name in (("\t", "tabs"), (";", "semicolons")):
        if sep in header:
            raise InputError(
                f"{src}: line {line}: not comma separated: {name} found in the header "
                f"({header.strip()[:60]!r}); a log is comma separated (FORMATS.md): save it "
                "with commas, or convert it with 'airbearing log import' (which reads tab "
                'and semicolon separated files, with decimal = "," for decimal commas)'
            )


def _to_pandas(table) -> pd.DataFrame:
    """An Arrow table as a DataFrame: one block per column (no consolidating copy) where
    pandas copies on write (pandas >= 3), so the arrays may stay Arrow's own."""
    split = int(pd.__version__.split(".")[0]) >= 3
    return table.to_pandas(split_blocks=split)


def _read_csv_fast(path: Path, wanted: set[str] | None) -> pd.DataFrame:
    """pyarrow's CSV reader: known columns as float64, others inferred (raises on any doubt)."""
    with path.open("rb") as fh:
        first = fh.readline()
    if first.startswith(b"\xef\xbb\xbf"):
        raise ValueError("a byte-order mark needs the careful reader")
    header = next(csv.reader([first.decode("utf-8")]))
    names = [h.strip() for h in header]
    if len(set(names)) != len(names) or any(h != n for h, n in zip(header, names, strict=True)):
        raise ValueError("header needs the careful reader")
    keep = [n for n in names if wanted is None or n in wanted]
    types = {name: pa.float64() for name in keep if name in LOG_COLUMNS}
    table = pacsv.read_csv(
        path,
        convert_options=pacsv.ConvertOptions(
            column_types=types,
            strings_can_be_null=False,
            quoted_strings_can_be_null=False,
            include_columns=keep,
        ),
    )
    if table.num_rows == 0 or any(table.column(n).null_count for n in types):
        raise ValueError("empty or missing cells need the careful reader")
    return _to_pandas(table)


def _wanted(columns: Iterable[str] | None, testbed: Testbed | None) -> set[str] | None:
    """The columns to read: ``columns`` plus ``t``, the testbed's required columns and,
    for a column of a group (the quaternion, the sliders...), the whole group."""
    if columns is None:
        return None
    wanted = {"t", *columns, *REQUIRED_COLUMNS(testbed)}
    if testbed is not None and testbed.body.dof == 1:
        wanted |= set(_QUATERNION)  # accepted in place of yaw
    if testbed is not None and testbed.wheels is not None:  # the commands come together
        wanted |= set(wheel_columns(testbed.wheels.n)[1])
    for group in COLUMN_GROUPS:
        if wanted & set(group):
            wanted |= set(group)
    return wanted


def read_log(
    path: str | os.PathLike[str],
    testbed: Testbed | None = None,
    *,
    columns: Iterable[str] | None = None,
) -> Log:
    """Read and validate a log file.

    Parameters
    ----------
    path : str or path-like
        A ``.csv`` (header row, comma separated, ``.`` decimal point) or
        ``.parquet`` file with the columns of FORMATS.md in SI units.
    testbed : Testbed, str, path-like or None
        The testbed the log belongs to (object, built-in name or testbed file); enables
        its column and sampling checks.
    columns : iterable of str or None
        Read only these columns (those the file has), with ``t``, the columns the
        testbed requires and the rest of any column group named (all four of
        ``qw .. qz``...); the file's other columns are not read, checked or kept.
        None (default): every column. A tool that uses a few columns of a wide
        log reads it faster this way.

    Returns
    -------
    Log

    Raises
    ------
    InputError
        If the suffix is not known, the file cannot be read, or the content
        fails :func:`validate_log`; CSV messages give the row (0-based data
        row) and the line of the file.

    Notes
    -----
    CSV is read by ``pyarrow.csv``; a file it refuses (or whose content is not
    valid) is read again cell by cell as text, so that the message names the
    row, the line and the column of the first bad cell.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> path = ab.write_log(ab.slew(tb, angle_deg=30.0, duration=2.0).log, "slew.csv")
    >>> log = ab.read_log(path, tb, columns=["yaw", "wz"])
    >>> log.n, log.has("yaw", "wz", "d1")  # the testbed requires the gimbal angles d1..d4
    (40, True)
    >>> ab.read_log("slew.txt")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: slew.txt: ...
    """
    testbed = as_testbed(testbed, optional=True)
    if not isinstance(path, str | os.PathLike):
        raise InputError(f"path={path!r}: expected a log file path (str or path-like)")
    p = Path(path)
    src = str(path)
    kind = _format(p)
    if not p.is_file():
        raise InputError(f"{src}: no such log file")
    wanted = _wanted(columns, testbed)
    if kind == "csv":
        try:
            fast = _read_csv_fast(p, wanted)
        except Exception:  # noqa: BLE001 (any doubt: the careful reader decides and explains)
            fast = None
        if fast is not None:
            try:
                data = _validate(fast, src, testbed, fresh=True)
                return Log._from_validated(data, src, testbed)
            except InputError:
                pass  # read again below, to name the line too
    try:
        if kind == "csv":
            df, lines = _read_csv(p, src)
            if wanted is not None:
                df = df[[c for c in df.columns if c in wanted]]
        else:
            names = pq.read_schema(p).names
            keep = None if wanted is None else [c for c in names if c in wanted]
            df, lines = _to_pandas(pq.read_table(p, columns=keep)), None
    except InputError:
        raise
    except Exception as e:  # pyarrow's errors (ArrowInvalid, OSError) on a bad file
        raise InputError(f"{src}: cannot read the {kind} log: {e}") from e
    data = _validate(df, src, testbed, lines, fresh=True)
    return Log._from_validated(data, src, testbed)


def _csv_bytes(data: pd.DataFrame) -> bytes:
    """CSV text by pyarrow (shortest round-trip floats); pandas for what arrow cannot type."""
    try:
        table = pa.Table.from_pandas(data, preserve_index=False)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, ValueError):
        return data.to_csv(index=False, lineterminator="\n").encode("utf-8")
    header = io.StringIO()
    csv.writer(header, lineterminator="\n").writerow([str(c) for c in data.columns])
    sink = io.BytesIO()
    sink.write(header.getvalue().encode("utf-8"))  # arrow would quote every name
    pacsv.write_csv(table, sink, pacsv.WriteOptions(include_header=False, quoting_style="needed"))
    return sink.getvalue()


def write_log(log: Log | pd.DataFrame, path: str | os.PathLike[str]) -> Path:
    """Write a log as CSV or Parquet (by suffix), atomically.

    Parameters
    ----------
    log : Log or pandas.DataFrame
        A DataFrame is validated first (without a testbed).
    path : str or path-like
        Destination, ``.csv`` or ``.parquet``; an existing file is replaced.
        Written by pyarrow; CSV floats are written with the shortest text that
        reads back to the same float (exact round trip).

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        If the suffix is unknown, the data is not a valid log, or the
        directory cannot be written. No partial file is left behind.

    Examples
    --------
    >>> import pandas as pd
    >>> import airbearing as ab
    >>> samples = pd.DataFrame({"t": [0.0, 0.05, 0.1], "yaw": [0.0, 0.01, 0.02],
    ...                         "wz": [0.2, 0.2, 0.2]})  # s, rad, rad/s
    >>> ab.write_log(samples, "run.parquet").name
    'run.parquet'
    >>> ab.read_log("run.parquet").column("wz").tolist()
    [0.2, 0.2, 0.2]
    """
    p = Path(path)
    kind = _format(p)
    if isinstance(log, Log):
        data = log.data
    elif isinstance(log, pd.DataFrame):
        data = _validate(log, str(path), None, unwrap_yaw=False)
    else:
        raise InputError(f"{path}: expected a Log or a pandas DataFrame, got {type(log).__name__}")
    if kind == "csv":
        content = _csv_bytes(data)
    else:
        buffer = io.BytesIO()
        pq.write_table(pa.Table.from_pandas(data, preserve_index=False), buffer)
        content = buffer.getvalue()
    return _atomic_write_bytes(p, content)
