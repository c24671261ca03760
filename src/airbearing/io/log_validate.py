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
:func:`validated`. The checks that need only the column names and float arrays are
:mod:`airbearing.io.log_checks`' (the readers apply them to a file's float64 columns
without a table); this module adds the table's: each cell's type and value.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from airbearing.errors import InputError
from airbearing.io.columns import _QUATERNION, LOG_COLUMNS, OVERFLOW_LIMIT, bad_mask, row_ranges
from airbearing.io.log_checks import (  # noqa: F401 (re-exported: this module's names)
    MEMORY_SOURCE,
    BadCellsError,
    _at,
    check_names,
    check_values,
    column_list,
    quaternion_norm_hint,
    restarts_at,
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


def table_of(arrays: dict[str, np.ndarray], attrs: dict) -> pd.DataFrame:
    """The DataFrame of validated float64 columns
    (:func:`~airbearing.io.log_checks.validated_arrays`): the columns in order, a fresh
    RangeIndex, ``attrs`` as given."""
    frame = pd.DataFrame(arrays, copy=False)
    frame.attrs.update(attrs)
    return frame


def is_table(obj: object) -> bool:
    """Whether ``obj`` is a :class:`pandas.DataFrame`."""
    return isinstance(obj, pd.DataFrame)


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
    check_names(columns, len(data), src, testbed)

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
    has_q = all(q in out.columns for q in _QUATERNION)
    check_values(t, [out[c].to_numpy() for c in _QUATERNION] if has_q else None, src,
                 testbed, lines)  # fmt: skip
    if unwrap_yaw:
        unwrap_wrapped_yaw(out, testbed)
    return out


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
