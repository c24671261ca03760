"""The checks of a log's samples that need only its column names and float arrays.

The rules of FORMATS.md ("Log (CSV or Parquet)") that :func:`~airbearing.io.log_validate.validated`
applies to a table: which columns a log (of a testbed) must have and which come together
(:func:`check_names`), time strictly increasing, a log that is not all gaps, its median
interval against ``1 / sensors.rate`` and unit quaternions (:func:`check_values`). The
readers use them directly on the float64 columns a file gives
(:func:`validated_arrays`, no pandas: importing it is 0.4-0.5 s of CPU of a new process,
what ``airbearing identify --method equation-error`` of a 10^4-row log must not spend);
anything else (a cell that is not a finite number, another type) goes through
:mod:`airbearing.io.log_validate`'s table, whose messages name the cell.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from airbearing.errors import InputError
from airbearing.io.columns import (
    _QUATERNION,
    COLUMN_GROUPS,
    GAP_FACTORS,
    LOG_COLUMNS,
    MIN_SEGMENT_ROWS,
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
from airbearing.io.log_yaw import YAW_UNWRAPPED, wrapped_yaw
from airbearing.io.testbed import Testbed

__all__ = [
    "MEMORY_SOURCE",
    "BadCellsError",
    "check_names",
    "check_values",
    "column_list",
    "quaternion_norm_hint",
    "restarts_at",
    "validated_arrays",
]

_MIN_ROWS = 2
#: The source of a log made in memory (not read from a file), in messages.
MEMORY_SOURCE = "<memory>"


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


def column_list(columns: Iterable[str]) -> str:
    """The names of ``columns`` joined by commas (for a message)."""
    return ", ".join(str(c) for c in columns)


def _check_wheel_columns(names: Sequence[str], src: str, testbed: Testbed | None) -> None:
    """``ws``/``wc`` columns against the testbed's wheel count (FORMATS.md: one per row of
    ``wheels.axes``); without a testbed, each family must run 1, 2, .. without a hole."""
    present = set(names)
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


def _check_required(src: str, testbed: Testbed, columns: Sequence[str]) -> None:
    who = f"testbed {testbed.name!r} (kind = {testbed.kind!r}, dof = {testbed.body.dof})"
    for column in REQUIRED_COLUMNS(testbed):
        if column in columns:
            continue
        if column == "yaw":
            if all(q in columns for q in _QUATERNION):
                continue
            raise InputError(
                f"{src}: missing column 'yaw' (rad; or the quaternion qw, qx, qy, qz), "
                f"needed by {who}; columns present: {column_list(columns)}"
            )
        raise InputError(
            f"{src}: missing column {column!r}, needed by {who}; "
            f"columns present: {column_list(columns)}"
        )


def _at(row: int, lines: Sequence[int] | None) -> str:
    """'row N' (0-based data row, header not counted), with the file line for CSV."""
    if lines is None:
        return f"row {row}"
    return f"row {row} (line {lines[row]})"


def check_names(names: Sequence[str], n_rows: int, src: str, testbed: Testbed | None) -> None:
    """The columns of a log: no name twice, ``t``, at least 2 rows, the testbed's required
    columns, its wheel columns and whole column groups (:func:`validated`'s first checks).

    Parameters
    ----------
    names : sequence of str
        The column names in the file's order.
    n_rows : int
        The number of data rows.
    src : str
        Name of the origin, for the message.
    testbed : Testbed or None
        The testbed the log belongs to.

    Raises
    ------
    InputError
        Naming the first problem.
    """
    seen: set = set()
    for name in names:
        if name in seen:
            raise InputError(f"{src}: column {name!r} appears more than once")
        seen.add(name)
    columns = list(names)
    if "t" not in seen:
        raise InputError(
            f"{src}: missing column 't' (time, s), which every log needs; "
            f"columns present: {column_list(columns)}"
        )
    if n_rows < _MIN_ROWS:
        raise InputError(f"{src}: a log needs at least {_MIN_ROWS} rows, got {n_rows}")
    if testbed is not None:
        _check_required(src, testbed, columns)
    _check_wheel_columns(columns, src, testbed)
    for group in COLUMN_GROUPS:
        have = [c for c in group if c in seen]
        if have and len(have) != len(group):
            missing = [c for c in group if c not in seen]
            raise InputError(
                f"{src}: missing column(s) {column_list(missing)}: the columns "
                f"{column_list(group)} come together (all or none), but only "
                f"{column_list(have)} given"
            )


def check_values(
    t: np.ndarray,
    quaternion: Sequence[np.ndarray] | None,
    src: str,
    testbed: Testbed | None,
    lines: Sequence[int] | None = None,
) -> None:
    """Time strictly increasing, a log not all gaps, its rate against the testbed's and
    unit quaternions (:func:`validated`'s checks of finite float values).

    Parameters
    ----------
    t : numpy.ndarray
        s, shape (n,), finite.
    quaternion : sequence of 4 numpy.ndarray, or None
        ``qw, qx, qy, qz`` when the log has them.
    src : str
        Name of the origin, for the message.
    testbed : Testbed or None
        Its ``sensors.rate`` says what a gap is and the expected interval.
    lines : sequence of int, optional
        The file line of each data row (a CSV file), named in the messages.

    Raises
    ------
    InputError
        :class:`BadCellsError` for time that does not increase or a non-unit quaternion.
    """
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
    if quaternion is not None:
        qw, qx, qy, qz = quaternion
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


def validated_arrays(
    names: Iterable[str],
    arrays: Mapping[str, np.ndarray],
    src: str,
    testbed: Testbed | None,
) -> tuple[dict[str, np.ndarray], dict] | None:
    """:func:`~airbearing.io.log_validate.validated` on float64 columns, without a table.

    Parameters
    ----------
    names : iterable of str
        The column names in the file's order.
    arrays : mapping of str to numpy.ndarray
        Each column as a float64 array of one length.
    src : str
        Name of the origin, for the message.
    testbed : Testbed or None
        As :func:`~airbearing.io.log_validate.validate_log`.

    Returns
    -------
    (dict, dict) or None
        The columns (a yaw written wrapped unwrapped) and the table's ``attrs``
        (``YAW_UNWRAPPED``); None when a cell of a FORMATS.md column is not a finite
        number (or overflow-sized): the table's validation names it.

    Raises
    ------
    InputError
        As :func:`check_names` and :func:`check_values` (the same messages as the table's).
    """
    names = list(names)
    n = len(arrays[names[0]]) if names else 0
    check_names(names, n, src, testbed)
    if any(bad_mask(arrays[c]).any() for c in names if c in LOG_COLUMNS):
        return None
    out = {c: arrays[c] for c in names}
    quaternion = [out[c] for c in _QUATERNION] if all(c in out for c in _QUATERNION) else None
    check_values(out["t"], quaternion, src, testbed)
    attrs: dict = {}
    if "yaw" in out:
        found = wrapped_yaw(out["yaw"], out["t"], testbed)
        if found is not None:
            out["yaw"], attrs = found[0], {YAW_UNWRAPPED: found[1]}
    return out, attrs


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
