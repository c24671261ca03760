"""Import maps (FORMATS.md, "Import map (TOML): a lab's own log -> a log"): read and validate.

An import map says how a lab's own log file (its column names, units, lab axis up,
quaternion direction and body axes) becomes a log of FORMATS.md. This module reads
and checks the map and the raw file's cells; the conversion itself, which needs the
quaternion algebra of :mod:`airbearing.quaternion`, is
:func:`airbearing.io.log_import.import_log`.

Besides the tables of FORMATS.md, a map may have the top-level keys of
:data:`FILE_KEYS` (airbearing's additions, for real exports): ``missing`` (dropouts
left out as a gap), ``decimal``, ``separator`` and ``restart`` (two runs in one file).

Every mistake is one :class:`~airbearing.errors.InputError` line naming the file and
the key, row (0-based data row) or column.
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from airbearing.errors import InputError
from airbearing.io.columns import LOG_COLUMNS, bad_mask, row_ranges
from airbearing.io.unwrap import unwrap

__all__ = [
    "COLUMN_QUANTITY",
    "FILE_KEYS",
    "LAB_UP",
    "MAPS",
    "UNITS",
    "ImportMap",
    "check_wheel_units",
    "import_map_from_dict",
    "raw_columns",
    "read_import_map",
    "missing_cells",
    "read_raw",
    "unwrap",
]

_MEMORY = "<memory>"
_ROTATION_TOL = 1e-6  # |C C^T - I| and |det C - 1| allowed for [frames] body

#: Units a raw column may have, by quantity: unit -> factor to the SI unit (FORMATS.md).
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9},
    "rate": {"rad/s": 1.0, "deg/s": math.pi / 180.0, "rpm": 2.0 * math.pi / 60.0},
    "angle": {"rad": 1.0, "deg": math.pi / 180.0},
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6},
    "dipole": {"A m^2": 1.0},
    "field": {"T": 1.0},
    "quaternion": {"-": 1.0},
    "torque": {"N m": 1.0, "mN m": 1e-3},
    # a wheel command wc is a torque, or a speed for speed-commanded wheels
    "wheel command": {
        "N m": 1.0,
        "mN m": 1e-3,
        "rad/s": 1.0,
        "deg/s": math.pi / 180.0,
        "rpm": 2.0 * math.pi / 60.0,
    },
}
#: The quantity of each log column (its unit table in :data:`UNITS`).
COLUMN_QUANTITY: dict[str, str] = {
    "t": "time",
    **{c: "quaternion" for c in ("qw", "qx", "qy", "qz")},
    "yaw": "angle",
    "yaw_ref": "angle",
    **{c: "rate" for c in ("wx", "wy", "wz")},
    **{c: "length" for c in ("s1", "s2", "s3")},
    **{c: "dipole" for c in ("mx", "my", "mz")},
    **{c: "field" for c in ("bx", "by", "bz")},
    **{c: "angle" for c in ("d1", "d2", "d3", "d4")},
    **{c: "rate" for c in ("dd1", "dd2", "dd3", "dd4")},
    **{f"ws{i}": "rate" for i in range(1, 7)},  # wheel speeds (per wheel: no [frames])
    **{f"wc{i}": "wheel command" for i in range(1, 7)},
}
#: Values of ``[quaternion] maps``.
MAPS: tuple[str, ...] = ("body_to_lab", "lab_to_body")
#: Values of ``[frames] lab_up``.
LAB_UP: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")
_TABLES: dict[str, tuple[str, ...] | None] = {
    "columns": None,  # keys: log columns
    "units": None,  # keys: log columns named in [columns]
    "quaternion": ("maps",),
    "frames": ("lab_up", "body"),
}
_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
#: Top-level keys of a map that say how the raw file is written (airbearing's additions to
#: FORMATS.md's map): key -> its valid values (the first is the default).
FILE_KEYS: dict[str, tuple[str | None, ...]] = {
    "missing": ("error", "gap"),  # blank or non-finite cells: an error, or rows left out
    "decimal": (".", ","),  # the decimal mark of the raw cells
    "separator": (None, ",", ";", "\t"),  # None: comma, or tab / ';' when the header has none
    "restart": ("error", "split"),  # time that restarts (two runs): an error, or one log per run
}
#: Cells that a lab's exporter writes for "no value" (besides a blank and a non-finite number).
MISSING_WORDS = frozenset(("na", "n/a", "null", "none", "-nan", "missing"))


@dataclass(frozen=True)
class ImportMap:
    """A validated import map.

    Attributes
    ----------
    columns : dict of str to str
        Log column -> the raw file's column (exact header text).
    units : dict of str to str
        Log column -> unit of the raw column (every mapped column; the SI unit
        where the map names none).
    maps : {"body_to_lab", "lab_to_body"}
        What the raw quaternion maps.
    lab_up : str
        The raw lab axis that points up, ``"+x"`` ... ``"-z"``.
    body : 3x3 tuple of float
        ``C``, rows = the testbed's body axes in raw body axes (``v_body = C v_raw``),
        a proper rotation.
    source : str
        The map's file (for messages).
    given_units : tuple of str
        The columns whose unit the map names in ``[units]`` (the others took the SI
        unit by default).
    missing : {"error", "gap"}
        A blank or non-finite cell in a mapped column: an error (default), or its row
        is left out of the log (a gap, reported by rows; nothing filled).
    decimal : {".", ","}
        The raw cells' decimal mark.
    separator : {None, ",", ";", "\\t"}
        The raw CSV's separator; None: a comma, or a tab or ``;`` when the header has no
        comma.
    restart : {"error", "split"}
        Time that restarts (two runs in one file): an error naming the row, or one log
        per run.
    """

    columns: dict[str, str]
    units: dict[str, str] = field(default_factory=dict)
    maps: str = "body_to_lab"
    lab_up: str = "+z"
    body: tuple[tuple[float, ...], ...] = _IDENTITY
    source: str = _MEMORY
    given_units: tuple[str, ...] = ()
    missing: str = "error"
    decimal: str = "."
    separator: str | None = None
    restart: str = "error"

    def factor(self, column: str) -> float:
        """Factor from the raw unit of a log column to its SI unit."""
        return UNITS[COLUMN_QUANTITY[column]][self.units[column]]

    @property
    def body_matrix(self) -> np.ndarray:
        """``C`` as an array, shape (3, 3)."""
        return np.array(self.body, dtype=float)


def _fail(src: str, key: str, expected: str, got: object) -> InputError:
    return InputError(f"{src}: key '{key}': expected {expected}, got {got!r}")


def _si_unit(column: str) -> str:
    return next(iter(UNITS[COLUMN_QUANTITY[column]]))


def import_map_from_dict(data: Mapping[str, Any], source: str = _MEMORY) -> ImportMap:
    """Validate the layout of an import map (FORMATS.md) and build an :class:`ImportMap`.

    Parameters
    ----------
    data : mapping
        The parsed TOML: ``[columns]`` (required), ``[units]``, ``[quaternion]``,
        ``[frames]``.
    source : str
        The map's name in messages.

    Returns
    -------
    ImportMap

    Raises
    ------
    InputError
        An unknown table or key (the message lists the valid ones), no
        ``[columns]``, a column that is not a log column or not a string, a unit
        for a column that is not mapped or not valid for its quantity (the
        message lists the valid units), an incomplete quaternion, an unknown
        ``maps`` or ``lab_up``, or a ``body`` that is not a rotation matrix.
    """
    src = str(source)
    if not isinstance(data, Mapping):
        raise InputError(f"{src}: expected tables of keys, got {data!r}")
    for key, value in data.items():
        if key in FILE_KEYS:
            continue  # checked by _file_keys
        if key not in _TABLES:
            raise InputError(
                f"{src}: unknown key '{key}'; an import map has the tables "
                + ", ".join(f"[{t}]" for t in _TABLES)
                + " and the top-level keys "
                + ", ".join(FILE_KEYS)
            )
        if not isinstance(value, Mapping):
            raise _fail(src, key, "a table", value)
        valid = _TABLES[key]
        for sub in value:
            if valid is not None and sub not in valid:
                raise InputError(
                    f"{src}: unknown key '{key}.{sub}'; valid keys in [{key}] are: "
                    + ", ".join(valid)
                )
            if valid is None and sub not in LOG_COLUMNS:
                _misplaced_file_key(src, key, sub)
                raise InputError(
                    f"{src}: unknown key '{key}.{sub}': not a log column; log columns are: "
                    + ", ".join(LOG_COLUMNS)
                )
    if "columns" not in data or not data["columns"]:
        raise InputError(
            f'{src}: table [columns] is required: log column = "raw column header", '
            'e.g. t = "Time (ms)"'
        )
    columns: dict[str, str] = {}
    for name, raw in data["columns"].items():
        if not isinstance(raw, str) or raw == "":
            raise _fail(src, f"columns.{name}", "the raw file's column header (a string)", raw)
        columns[name] = raw
    if "t" not in columns:
        raise InputError(f"{src}: key 'columns.t' is required: the raw column of time")
    quaternion = [c for c in ("qw", "qx", "qy", "qz") if c in columns]
    if quaternion and len(quaternion) != 4:
        missing = [c for c in ("qw", "qx", "qy", "qz") if c not in columns]
        raise InputError(
            f"{src}: key 'columns.{missing[0]}' is missing: the quaternion needs all four "
            "of qw, qx, qy, qz (scalar-last files simply name their columns)"
        )
    units: dict[str, str] = {}
    for name, unit in data.get("units", {}).items():
        if name not in columns:
            raise InputError(
                f"{src}: key 'units.{name}': column {name!r} is not in [columns]; "
                f"mapped columns are: {', '.join(columns)}"
            )
        valid_units = UNITS[COLUMN_QUANTITY[name]]
        if not isinstance(unit, str) or unit not in valid_units:
            raise _fail(
                src,
                f"units.{name}",
                f"{'an' if COLUMN_QUANTITY[name][0] in 'aeiou' else 'a'} "
                f"{COLUMN_QUANTITY[name]} unit, one of {', '.join(valid_units)}",
                unit,
            )
        units[name] = unit
    given = tuple(units)
    units = {name: units.get(name, _si_unit(name)) for name in columns}
    maps = data.get("quaternion", {}).get("maps", "body_to_lab")
    if maps not in MAPS:
        raise _fail(src, "quaternion.maps", "one of " + ", ".join(repr(m) for m in MAPS), maps)
    frames = data.get("frames", {})
    lab_up = frames.get("lab_up", "+z")
    if lab_up not in LAB_UP:
        raise _fail(src, "frames.lab_up", "one of " + ", ".join(repr(a) for a in LAB_UP), lab_up)
    body = _rotation(frames.get("body", [list(r) for r in _IDENTITY]), src)
    return ImportMap(columns, units, maps, lab_up, body, src, given, **_file_keys(data, src))


def _misplaced_file_key(src: str, table: str, key: str) -> None:
    """A top-level key written after a table header lands in that table (TOML): say so."""
    if key in FILE_KEYS:
        raise InputError(
            f"{src}: key '{table}.{key}': {key!r} is a top-level key of the map; TOML puts a "
            f"key written after [{table}] into that table: move '{key} = ...' above the "
            "first [table]"
        )


def _file_keys(data: Mapping[str, Any], src: str) -> dict[str, str | None]:
    """The top-level keys of :data:`FILE_KEYS` (how the raw file is written), checked."""
    out: dict[str, str | None] = {}
    for key, valid in FILE_KEYS.items():
        value = data.get(key, valid[0])
        if value == "tab" and key == "separator":
            value = "\t"
        if value not in valid or (value is None and key in data):
            shown = ", ".join(repr(v) for v in valid if v is not None)
            raise _fail(src, key, f"one of {shown}", value)
        out[key] = value
    if out["decimal"] == "," and out["separator"] == ",":
        raise InputError(
            f"{src}: keys 'decimal' and 'separator': a decimal comma needs another separator; "
            'expected separator = ";" (or "\\t")'
        )
    return out


def _rotation(value: object, src: str) -> tuple[tuple[float, ...], ...]:
    what = "a 3x3 rotation matrix (rows: testbed body axes in raw body axes)"
    ok = (
        isinstance(value, list | tuple)
        and len(value) == 3
        and all(isinstance(r, list | tuple) and len(r) == 3 for r in value)
        and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
            for r in value
            for v in r
        )
    )
    if not ok:
        raise _fail(src, "frames.body", what, value)
    c = np.array(value, dtype=float)
    off = float(np.max(np.abs(c @ c.T - np.eye(3))))
    det = float(np.linalg.det(c))
    if off > _ROTATION_TOL or abs(det - 1.0) > _ROTATION_TOL:
        why = (
            f"C C^T differs from the identity by {off:.3g}"
            if off > _ROTATION_TOL
            else f"det C = {det:.6g} (a reflection, not a rotation)"
        )
        raise InputError(f"{src}: key 'frames.body': expected {what}, but {why}")
    return tuple(tuple(float(v) for v in r) for r in value)  # type: ignore[union-attr]


def read_import_map(path: str | os.PathLike[str]) -> ImportMap:
    """Read and validate an import map file (TOML).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    ImportMap

    Raises
    ------
    InputError
        If the file is missing, not TOML, or not a valid map (:func:`import_map_from_dict`).

    Examples
    --------
    >>> from pathlib import Path
    >>> import airbearing as ab
    >>> _ = Path("lab.toml").write_text(
    ...     '[columns]\\nt = "Time (ms)"\\nyaw = "Yaw (deg)"\\n[units]\\nt = "ms"\\nyaw = "deg"\\n')
    >>> found = ab.read_import_map("lab.toml")
    >>> found.columns, found.units
    ({'t': 'Time (ms)', 'yaw': 'Yaw (deg)'}, {'t': 'ms', 'yaw': 'deg'})
    """
    src = str(path)
    try:
        content = Path(path).read_bytes()
    except FileNotFoundError as e:
        raise InputError(f"{src}: no such import map file") from e
    except OSError as e:
        raise InputError(f"{src}: cannot read the import map: {e.strerror}") from e
    try:
        data = tomllib.loads(content.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise InputError(f"{src}: not valid TOML: {e}") from e
    return import_map_from_dict(data, src)


def read_raw(path: str | os.PathLike[str], separator: str | None = None, decimal: str = "."):
    """Read a lab's raw log (CSV, or Parquet by suffix) with every cell kept as it is.

    Parameters
    ----------
    path : str or path-like
    separator : str or None
        The CSV separator (an import map's ``separator``); None: a comma, or a tab or
        semicolon when the header has no comma.
    decimal : {".", ","}
        The cells' decimal mark: with ``","`` the separator must be another one.

    Returns
    -------
    pandas.DataFrame
        CSV (comma, or tab or semicolon when the header has no comma; a UTF-8
        byte-order mark ignored) cells as text (nothing turned into NaN behind the
        reader's back),
        Parquet columns as stored. Row ``i`` is data row ``i`` (0-based).

    Raises
    ------
    InputError
        If the file is missing, empty or not readable.
    """
    p = Path(path)
    src = str(path)
    if not p.is_file():
        raise InputError(f"{src}: no such raw log file")
    try:
        if p.suffix.lower() in (".parquet", ".pq"):
            return pq.read_table(p).to_pandas()
        with p.open(encoding="utf-8-sig") as fh:
            header = fh.readline()
        sep = separator or ","
        if separator is None and "," not in header:  # a lab's export: tabs or semicolons
            sep = "\t" if "\t" in header else (";" if ";" in header else ",")
        if decimal == "," and sep == ",":
            raise InputError(
                f'{src}: the header is comma separated, but the map says decimal = ",": '
                'expected cells separated by ";" or tabs (set separator = ";" if the header '
                "holds commas in its names)"
            )
        return pd.read_csv(
            p,
            sep=sep,
            dtype=str,
            keep_default_na=False,
            skip_blank_lines=True,
            encoding="utf-8-sig",  # a byte-order mark is not part of the first header
        )
    except InputError:
        raise
    except pd.errors.EmptyDataError as e:
        raise InputError(f"{src}: the raw log is empty; expected a header row") from e
    except Exception as e:  # noqa: BLE001 (any reader failure is a bad file)
        raise InputError(f"{src}: cannot read the raw log: {str(e).strip()}") from e


def raw_columns(raw, import_map: ImportMap, src: str, skip: tuple[str, ...] = ()):
    """The mapped raw columns as float arrays in SI units.

    Parameters
    ----------
    raw : pandas.DataFrame
        From :func:`read_raw`.
    import_map : ImportMap
    src : str
        The raw file's name, for messages.
    skip : tuple of str
        Log columns not to convert (ignored, e.g. rates without a gyro).

    Returns
    -------
    dict of str to numpy.ndarray
        Log column -> values times the unit's factor (``t = raw time x unit``,
        never shifted); with the map's ``missing = "gap"``, NaN where a cell has no value
        (:func:`missing_cells`: the import leaves those rows out as a gap). Cells are read
        with the map's ``decimal`` mark.

    Raises
    ------
    InputError
        A mapped column missing from the file (the message lists the file's
        columns), a cell that is not a finite number or is overflow-sized (the log's
        rule, :func:`airbearing.io.columns.bad_mask`; rows and column named), or a time
        column in s by default whose median interval is :data:`SLOWEST_INTERVAL` or
        more (the message asks whether it is in ms), or one in ms, us or ns whose
        median interval is shorter than ``1 / FASTEST_RATE`` s (asks whether it is in s).
    """
    headers = [str(c) for c in raw.columns]
    stripped = {h.strip(): h for h in headers}
    out: dict[str, np.ndarray] = {}
    for name, header in import_map.columns.items():
        if name in skip:
            continue
        actual = header if header in headers else stripped.get(header.strip())
        if actual is None:
            glued = len(headers) == 1 and any(c in headers[0] for c in ",;\t")
            raise InputError(
                f"{src}: no column {header!r} (map {import_map.source}, key 'columns.{name}'); "
                f"the file has: {', '.join(repr(h) for h in headers)}"
                + ("; is the map's separator the file's?" if glued else "")
            )
        cells = raw[actual]
        if pd.api.types.is_bool_dtype(cells.dtype):
            values = np.full(len(cells), np.nan)
        elif pd.api.types.is_numeric_dtype(cells.dtype):
            values = cells.to_numpy(dtype=float, na_value=np.nan)
        else:
            text = cells.astype(str).str.strip()
            if import_map.decimal == ",":
                text = text.str.replace(",", ".", regex=False)
            values = pd.to_numeric(text, errors="coerce").to_numpy(dtype=float, na_value=np.nan)
        bad = bad_mask(values)
        blank = missing_cells(cells, values) if bad.any() else bad
        if import_map.missing == "gap":
            bad &= ~blank  # left out as a gap by the import (reported by rows)
            values = np.where(blank, np.nan, values)
        if bad.any():
            i = int(np.argmax(bad))
            rows = np.flatnonzero(bad)
            more = f" ({len(rows)} such rows: {row_ranges(rows)})" if len(rows) > 1 else ""
            raise InputError(
                f"{src}: row {i}, column {actual!r} (log column {name!r}): expected a finite "
                f"number of magnitude at most 1e+100, got {cells.iloc[i]!r}{more}"
                + _cell_hint(cells.iloc[i], bool(np.all(blank[bad])), import_map)
            )
        if name == "t" and "t" not in import_map.given_units and len(values) > 1:
            _check_seconds(values, src, actual, import_map.source)
        elif name == "t" and import_map.units[name] != "s" and len(values) > 1:
            _check_sub_unit(values, src, actual, import_map.units[name], import_map.source)
        factor = import_map.factor(name)
        inverse = round(1.0 / factor)
        if factor < 1.0 and abs(1.0 / factor - inverse) < 1e-9 * inverse:
            out[name] = values / inverse  # ms -> s as raw / 1000: correctly rounded
        else:
            out[name] = values * factor
    return out


def missing_cells(cells, values: np.ndarray) -> np.ndarray:
    """Cells with no value: blank, a non-finite number (``NaN``, ``inf``) or a word an
    exporter writes for none (:data:`MISSING_WORDS`), shape (n,), bool."""
    out = ~np.isfinite(values) & ~np.isnan(values)  # inf, -inf
    if pd.api.types.is_numeric_dtype(cells.dtype) and not pd.api.types.is_bool_dtype(cells.dtype):
        return out | np.isnan(values)
    text = cells.astype(str).str.strip().str.lower()
    nan_text = text.isin(("nan", "+nan", "-nan", "")) | text.isin(MISSING_WORDS)
    return out | nan_text.to_numpy(dtype=bool) | cells.isna().to_numpy(dtype=bool)


def _cell_hint(cell: object, all_missing: bool, import_map: ImportMap) -> str:
    """The map setting that would read a refused cell, in words ("" when none would)."""
    where = f" in {import_map.source}" if import_map.source != _MEMORY else ""
    if all_missing:
        return (
            f'; if these are dropouts (blank or NaN cells), set missing = "gap"{where} to '
            "leave those rows out as a gap (reported by rows, never filled)"
        )
    if (
        import_map.decimal == "."
        and isinstance(cell, str)
        and re.fullmatch(r"[+-]?\d*,\d+([eE][+-]?\d+)?", cell.strip())
    ):
        return (
            f'; a decimal comma? set decimal = ","{where} (with separator = ";" when the file '
            "is separated by semicolons)"
        )
    return ""


#: s: a time column read in s (no ``[units] t``) whose median interval is this or more is
#: taken for milliseconds or microseconds read as seconds: air-bearing logs sample at
#: 1 Hz or faster (attitude control and identification need it), while a 10-100 Hz
#: log in ms gives median intervals of 10-100 "s".
SLOWEST_INTERVAL = 1.0


def _check_seconds(t: np.ndarray, src: str, header: str, map_src: str) -> None:
    dt = np.diff(t)
    dt = dt[dt > 0]
    if not dt.size:
        return
    median = float(np.median(dt))
    if median < SLOWEST_INTERVAL:
        return
    guess = "us" if median >= 1e3 * SLOWEST_INTERVAL else "ms"
    raise InputError(
        f"{src}: column {header!r} (log column 't'): median interval {median:.4g} s; is the "
        f'time column in {guess}? set [units] t = "{guess}" in {map_src} (or t = "s" if '
        "the samples really are that far apart)"
    )


#: Hz: a time column in ms, us or ns whose median interval is shorter than 1 / this is
#: taken for seconds (or a larger unit) mislabelled: air-bearing loggers sample at 1 Hz to
#: 1 kHz, while a 10-100 Hz log in s read as ms gives 10-100 kHz.
FASTEST_RATE = 5000.0


def _check_sub_unit(t: np.ndarray, src: str, header: str, unit: str, map_src: str) -> None:
    dt = np.diff(t)
    dt = dt[dt > 0]
    if not dt.size:
        return
    median = float(np.median(dt)) * UNITS["time"][unit]  # s
    if median * FASTEST_RATE >= 1.0:
        return
    raise InputError(
        f"{src}: column {header!r} (log column 't'): median interval {median:.4g} s "
        f"({1.0 / median:.4g} Hz) read as {unit} ([units] t = {unit!r} in {map_src}); "
        f"faster than {FASTEST_RATE:g} Hz, which no air-bearing logger samples at: is the "
        f'time column in s? set [units] t = "s" (or the unit the file really uses)'
    )


def check_wheel_units(import_map: ImportMap, testbed) -> None:
    """A wheel command's unit against ``wheels.command``: a torque unit (N m, mN m) for
    torque-commanded wheels, a rate unit (rad/s, deg/s, rpm) for speed-commanded ones.

    Raises
    ------
    InputError
        Naming the map's key ``units.wcN`` and what the testbed's wheels take.
    """
    wheels = getattr(testbed, "wheels", None)
    if wheels is None:
        return
    torque = wheels.command == "torque"
    valid = UNITS["torque"] if torque else UNITS["rate"]
    for name in import_map.given_units:
        if COLUMN_QUANTITY.get(name) != "wheel command":
            continue
        unit = import_map.units[name]
        if unit not in valid:
            raise InputError(
                f"{import_map.source}: key 'units.{name}': expected a "
                f"{'torque' if torque else 'rate'} unit, one of {', '.join(valid)} (testbed "
                f"{testbed.name!r} has wheels.command = {wheels.command!r}), got {unit!r}"
            )
