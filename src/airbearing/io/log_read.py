"""Reading a log file (CSV or Parquet, FORMATS.md) into validated samples.

Files are read with pyarrow (``pyarrow.csv``, ``pyarrow.parquet``). A table whose every
column is float64 without a missing cell (the usual log) is checked on its arrays
(:mod:`airbearing.io.log_checks`, no pandas); any other goes through a DataFrame
(:mod:`airbearing.io.log_validate`). A CSV that the fast reader refuses, or whose content
is not valid, is read again cell by cell as text so that the error names the row, the
line and the column. The
front door is :func:`airbearing.io.log.read_log`, which wraps the samples in a
:class:`~airbearing.io.log.Log`.
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from airbearing.errors import InputError
from airbearing.io.columns import (
    _QUATERNION,
    COLUMN_GROUPS,
    LOG_COLUMNS,
    REQUIRED_COLUMNS,
    wheel_columns,
)
from airbearing.io.log_checks import validated_arrays
from airbearing.io.testbed import Testbed

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["LOG_SUFFIXES", "log_format", "read_table"]

_CSV_SUFFIXES = (".csv",)
_PARQUET_SUFFIXES = (".parquet", ".pq")
#: The suffixes of log files (lower case): CSV, then Parquet.
LOG_SUFFIXES = _CSV_SUFFIXES + _PARQUET_SUFFIXES


def log_format(path: Path) -> str:
    """A log file's format by its suffix.

    Parameters
    ----------
    path : pathlib.Path
        The file (it need not exist).

    Returns
    -------
    str
        ``"csv"`` or ``"parquet"``.

    Raises
    ------
    InputError
        If the suffix is not one of :data:`LOG_SUFFIXES`.
    """
    suffix = path.suffix.lower()
    if suffix in _CSV_SUFFIXES:
        return "csv"
    if suffix in _PARQUET_SUFFIXES:
        return "parquet"
    raise InputError(
        f"{path}: unknown log format {path.suffix!r}; expected one of {', '.join(LOG_SUFFIXES)}"
    )


def _read_csv(path: Path, src: str) -> tuple[pd.DataFrame, list[int] | None]:
    import pandas as pd  # 0.4-0.5 s CPU to import: only a CSV the fast reader refuses

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
    import pandas as pd  # 0.4-0.5 s CPU to import: only a log with other than float64 columns

    split = int(pd.__version__.split(".")[0]) >= 3
    return table.to_pandas(split_blocks=split)


def _float_columns(table, src: str, testbed: Testbed | None):
    """A table whose every column is float64 without a missing cell, checked as
    :func:`~airbearing.io.log_validate.validated` checks it but on its arrays (no pandas):
    ``(arrays, attrs)``; None for any other table (the table's validation decides)."""
    names = table.column_names
    if len(set(names)) != len(names):
        return None
    for column in table.columns:
        if not pa.types.is_float64(column.type) or column.null_count:
            return None
    arrays = {name: _float64(table.column(i)) for i, name in enumerate(names)}
    return validated_arrays(names, arrays, src, testbed)


def _float64(column) -> np.ndarray:
    """A float64 Arrow column without missing cells as a NumPy array on Arrow's memory
    (read-only); Arrow's own ``to_numpy`` imports pandas (0.4-0.5 s CPU)."""
    array = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    if len(array) == 0:
        return np.zeros(0)
    return np.frombuffer(array.buffers()[1], np.float64, len(array), array.offset * 8)


def _validated_table(table, src: str, testbed: Testbed | None, lines=None) -> pd.DataFrame:
    """:func:`~airbearing.io.log_validate.validated` of an Arrow table (as a DataFrame)."""
    # pandas (0.4-0.5 s CPU to import): only a log with other than float64 columns
    from airbearing.io.log_validate import validated

    df = _to_pandas(table) if isinstance(table, pa.Table) else table
    return validated(df, src, testbed, lines, fresh=True)


def _read_csv_fast(path: Path, wanted: set[str] | None) -> pa.Table:
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
    return table


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


def read_table(
    path: str | os.PathLike[str],
    testbed: Testbed | None = None,
    columns: Iterable[str] | None = None,
) -> tuple[dict[str, np.ndarray], dict] | pd.DataFrame:
    """A log file's samples, read and validated (:func:`airbearing.io.log.read_log`'s work).

    Parameters
    ----------
    path : str or path-like
        A ``.csv`` or ``.parquet`` log file (FORMATS.md).
    testbed : Testbed or None
        The testbed the log belongs to (an object: :func:`~airbearing.io.log.read_log`
        resolves names and files).
    columns : iterable of str or None
        Read only these columns (and those they bring, :func:`~airbearing.io.log.read_log`);
        None: every column.

    Returns
    -------
    (dict, dict) or pandas.DataFrame
        When every column read is float64 without a missing cell (the usual log): its
        arrays by name in the file's order and the table's ``attrs``, checked by
        :func:`~airbearing.io.log_checks.validated_arrays` (no pandas); else the samples
        as :func:`~airbearing.io.log_validate.validate_log` returns them.

    Raises
    ------
    InputError
        As :func:`~airbearing.io.log.read_log`.
    """
    try:
        return _read_table(path, testbed, columns)
    finally:  # the file's table is let go of by now
        release_arrow_memory()


def release_arrow_memory() -> None:
    """Hand the pages Arrow's memory pool keeps free back to the system.

    Arrow's default pool (mimalloc or jemalloc) keeps what a read frees in the heaps of
    the threads that read, idle from then on: reading an hour of 50 Hz three-axis samples
    (21 columns, 7 of them of inferred type) left ~90 MB of free pages resident through the
    whole search, of no use to NumPy's allocations. The system pool (glibc's malloc,
    :func:`airbearing.cli.process_settings.reuse_freed_memory`) is left to its own policy.
    """
    pool = pa.default_memory_pool()
    if pool.backend_name != "system":
        pool.release_unused()


def _read_table(path, testbed, columns):
    """:func:`read_table`'s work."""
    if not isinstance(path, str | os.PathLike):
        raise InputError(f"path={path!r}: expected a log file path (str or path-like)")
    p = Path(path)
    src = str(path)
    kind = log_format(p)
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
                return _float_columns(fast, src, testbed) or _validated_table(fast, src, testbed)
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
            # (one file: pq.read_table's dataset layer would import pandas, 0.4-0.5 s CPU)
            table = pq.ParquetFile(p).read(columns=keep)
    except InputError:
        raise
    except Exception as e:  # pyarrow's errors (ArrowInvalid, OSError) on a bad file
        raise InputError(f"{src}: cannot read the {kind} log: {e}") from e
    if kind == "csv":
        return _validated_table(df, src, testbed, lines)
    return _float_columns(table, src, testbed) or _validated_table(table, src, testbed)
