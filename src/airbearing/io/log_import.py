"""A lab's own log -> a log of FORMATS.md, by an import map (FORMATS.md, "Import map").

The map and the raw cells are read and checked by :mod:`airbearing.io.import_map`;
this module converts (units, lab axis up, quaternion direction, body axes, yaw
unwrapping) with the one quaternion module, :mod:`airbearing.quaternion` (below every
layer, so the whole import map lives in ``io``).

The import never drops, reorders, fills, smooths or resamples a row: row ``i`` of
the raw file is row ``i`` of the log.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.io.import_map import (
    ImportMap,
    check_wheel_units,
    import_map_from_dict,
    raw_columns,
    read_import_map,
    read_raw,
    unwrap,
)
from airbearing.io.log import (
    LOG_COLUMNS,
    QUATERNION_NORM_TOL,
    RATE_COLUMNS,
    Log,
    quaternion_norm_hint,
    restarts_at,
    row_ranges,
)
from airbearing.io.testbed import Testbed

__all__ = [
    "ImportResult",
    "import_log",
    "import_log_with_notes",
    "lab_up_quaternion",
    "leave_out_missing",
    "time_runs",
    "unwrap",
]

_QUATERNION = ("qw", "qx", "qy", "qz")
_BODY_VECTORS = (("wx", "wy", "wz"), ("mx", "my", "mz"), ("bx", "by", "bz"))
_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class ImportResult:
    """An imported log and what the import says about it.

    Attributes
    ----------
    log : Log
        The log (validated, with the testbed if one was given).
    notes : tuple of str
        Sentences for the user (ignored rate columns, renormalised quaternions).
    ignored : tuple of str
        Log columns of the map that were not imported.
    logs : tuple of Log
        One log per run: a file whose time restarts holds several runs, imported one
        log each with the map's ``restart = "split"`` (else just :attr:`log`).
    runs : tuple of (int, int)
        Raw rows ``(first, last + 1)`` of each log of :attr:`logs`.
    left_out : tuple of int
        Raw rows with a blank or non-finite cell, left out as a gap (the map's
        ``missing = "gap"``); the log has no row for them.
    """

    log: Log
    notes: tuple[str, ...] = ()
    ignored: tuple[str, ...] = ()
    logs: tuple[Log, ...] = ()
    runs: tuple[tuple[int, int], ...] = ()
    left_out: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not self.logs:
            object.__setattr__(self, "logs", (self.log,))


def lab_up_quaternion(lab_up: str) -> np.ndarray:
    """``q_up``: the smallest rotation taking the raw lab axis ``lab_up`` to +z.

    For ``"+y"``: ``x_lab = x_raw, y_lab = -z_raw, z_lab = y_raw``; for ``"-z"`` a
    half turn about x (FORMATS.md).
    """
    sign = -1.0 if lab_up[0] == "-" else 1.0
    axis = sign * np.array(_AXES[lab_up[1]])
    if lab_up == "-z":
        return quat.from_axis_angle([1.0, 0.0, 0.0], np.pi)
    return quat.between(axis, [0.0, 0.0, 1.0])


def _quaternion_of_matrix(c: np.ndarray) -> np.ndarray:
    """Unit quaternion whose ``rotation_matrix`` is ``c`` (scalar first)."""
    x, y, z, w = Rotation.from_matrix(c).as_quat()
    q = np.array([w, x, y, z])
    if not np.allclose(quat.rotation_matrix(q), c, atol=1e-9):  # same convention as models
        raise RuntimeError("quaternion of a frame rotation: conventions disagree")
    return q


def _body_vectors(values: dict, c: np.ndarray, src: str) -> None:
    """``v = C v_raw`` for rates, dipoles and fields, in place."""
    for group in _BODY_VECTORS:
        have = [i for i, name in enumerate(group) if name in values]
        if not have:
            continue
        if len(have) == 3:
            raw = np.column_stack([values[name] for name in group])
            new = raw @ c.T
            for i, name in enumerate(group):
                values[name] = new[:, i]
            continue
        mixes = any(abs(c[i, j]) > 0 for i in have for j in range(3) if j not in have)
        if mixes:
            names = ", ".join(group[i] for i in have)
            raise InputError(
                f"{src}: key 'frames.body': the map gives only {names} of {', '.join(group)}, "
                "but the body rotation mixes in the other axes; map all three columns"
            )
        sub = c[np.ix_(have, have)]
        raw = np.column_stack([values[group[i]] for i in have])
        new = raw @ sub.T
        for k, i in enumerate(have):
            values[group[i]] = new[:, k]


def import_log_with_notes(
    raw: str | os.PathLike[str] | object,
    import_map: ImportMap | str | os.PathLike[str],
    testbed: Testbed | None = None,
    *,
    source: str | None = None,
) -> ImportResult:
    """Convert a lab's raw log into a log (FORMATS.md, "Import map").

    Parameters
    ----------
    raw : path or pandas.DataFrame
        The raw file (CSV, or Parquet by suffix) or its table (cells as read).
    import_map : ImportMap, path or dict
        The map (a TOML file is read with :func:`airbearing.io.import_map.read_import_map`;
        a dict in the TOML layout is checked by
        :func:`~airbearing.io.import_map.import_map_from_dict`).
    testbed : Testbed, str, path-like or None
        A testbed, a built-in name or a testbed file. If given, the log is validated
        against it (required columns, gaps) and, with ``sensors.gyro = false``, the map's
        rate columns are ignored (said in :attr:`ImportResult.notes`).
    source : str or None
        Name of the raw data in messages (default: the path, or ``"<raw>"``).

    Returns
    -------
    ImportResult
        The log (``t`` in s, never shifted; angles rad; rates rad/s; lengths m;
        ``q = q_up (x) q_raw (x) conj(q_C)``, after conjugating ``q_raw`` when
        ``maps = "lab_to_body"``, renormalised; ``w, m, b = C v_raw``; ``yaw``
        unwrapped per segment by :func:`unwrap`), its notes and ignored columns.

    Raises
    ------
    InputError
        A bad map, a mapped column missing from the file, a non-numeric or
        non-finite cell, a quaternion whose norm is off 1 by more than 1e-3, or a
        result that is not a valid log (time not increasing, all gaps, ...): one
        line naming the key, row (0-based data row) or column.

    Examples
    --------
    A raw file with a millisecond clock and the yaw in degrees, wrapped at 180 deg:

    >>> from pathlib import Path
    >>> import airbearing as ab
    >>> _ = Path("raw.csv").write_text("Time (ms),Yaw (deg)\\n0,179\\n100,-179\\n200,-177\\n")
    >>> mapping = {"columns": {"t": "Time (ms)", "yaw": "Yaw (deg)"},
    ...            "units": {"t": "ms", "yaw": "deg"}}
    >>> imported = ab.import_log_with_notes("raw.csv", mapping)
    >>> imported.log.t.tolist()  # s
    [0.0, 0.1, 0.2]
    >>> [round(float(y), 4) for y in imported.log.yaw()]  # rad, unwrapped (said in .notes)
    [3.1241, 3.159, 3.194]
    """
    import_map = _as_import_map(import_map)
    testbed = as_testbed(testbed, optional=True)
    if source is not None and not isinstance(source, str):
        raise InputError(f"source={source!r}: expected a str (the raw data's name) or None")
    if isinstance(raw, pd.DataFrame):
        src = source or "<raw>"
        table = raw
    elif not isinstance(raw, str | os.PathLike):
        raise InputError(
            f"raw={raw!r:.60}: expected a raw log file path (str or path-like) or a "
            "pandas.DataFrame"
        )
    else:
        src = source or str(raw)
        table = read_raw(Path(raw), import_map.separator, import_map.decimal)  # type: ignore[arg-type]
    notes: list[str] = []
    skip: tuple[str, ...] = ()
    if testbed is not None and not testbed.sensors.gyro:
        skip = tuple(c for c in RATE_COLUMNS if c in import_map.columns)
        if skip:
            named = ", ".join(f"{c} ({import_map.columns[c]!r})" for c in skip)
            notes.append(
                f"sensors.gyro = false in testbed {testbed.name!r}: rate column(s) {named} "
                "ignored (attitude-only log)"
            )
    check_wheel_units(import_map, testbed)
    values = raw_columns(table, import_map, src, skip)
    values, raw_rows, gap_notes = leave_out_missing(values, import_map)
    notes += gap_notes
    runs = time_runs(values["t"], raw_rows, import_map, src)
    c = import_map.body_matrix

    if all(name in values for name in _QUATERNION):
        q = np.column_stack([values[name] for name in _QUATERNION])
        norm = np.linalg.norm(q, axis=1)
        off = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
        if off.any():
            k = int(np.argmax(off))
            cols = ", ".join(repr(import_map.columns[n]) for n in _QUATERNION)
            rows = raw_rows[off]
            more = f"; {rows.size} such rows: {row_ranges(rows)}" if rows.size > 1 else ""
            raise InputError(
                f"{src}: row {raw_rows[k]}, columns {cols}: expected a unit quaternion (norm "
                f"within {QUATERNION_NORM_TOL:g} of 1 is renormalised), got norm "
                f"{norm[k]:.9g}{more}" + quaternion_norm_hint(norm)
            )
        renormalised = int(np.count_nonzero(np.abs(norm - 1.0) > 1e-12))
        q = q / norm[:, None]
        if import_map.maps == "lab_to_body":
            q = quat.qconj(q)
        q_up = lab_up_quaternion(import_map.lab_up)
        q_c = _quaternion_of_matrix(c)
        q = quat.qmul(quat.qmul(q_up, q), quat.qconj(q_c))  # FORMATS.md import map
        for k, name in enumerate(_QUATERNION):
            values[name] = q[:, k]
        if renormalised:
            notes.append(f"{renormalised} quaternion(s) renormalised (norm within 1e-3 of 1)")
    _body_vectors(values, c, import_map.source)
    logs = []
    for k, (a, b) in enumerate(runs):
        run = {name: v[a:b] for name, v in values.items()}
        if "yaw" in run:
            yaw = unwrap(run["yaw"], run["t"])
            notes += _unwrap_note(yaw - run["yaw"], raw_rows[a:b], import_map)
            run["yaw"] = yaw
        columns = {name: run[name] for name in LOG_COLUMNS if name in run}
        name = src if len(runs) == 1 else f"{src} (run {k + 1}: raw rows {raw_rows[a]}-"
        name += "" if len(runs) == 1 else f"{raw_rows[b - 1]})"
        logs.append(Log(pd.DataFrame(columns), source=name, testbed=testbed))
    spans = tuple((int(raw_rows[a]), int(raw_rows[b - 1]) + 1) for a, b in runs)
    left = np.setdiff1d(np.arange(len(table)), raw_rows)
    return ImportResult(
        logs[0], tuple(notes), skip, tuple(logs), spans, tuple(int(r) for r in left)
    )


def leave_out_missing(
    values: dict[str, np.ndarray], import_map: ImportMap
) -> tuple[dict[str, np.ndarray], np.ndarray, list[str]]:
    """Rows with a missing cell left out (the map's ``missing = "gap"``), and said.

    Parameters
    ----------
    values : dict of str to numpy.ndarray
        Log column -> raw values in SI units, NaN where a cell had no value
        (:func:`airbearing.io.import_map.raw_columns`).
    import_map : ImportMap

    Returns
    -------
    values : dict of str to numpy.ndarray
        Without those rows (nothing filled: the log has no row for them, and the
        interval across them is a gap).
    raw_rows : numpy.ndarray
        The raw row of each row kept, shape (n_kept,).
    notes : list of str
        The rows left out, by run of rows, and which raw columns had no value.
    """
    n = len(values["t"])
    missing = np.zeros(n, dtype=bool)
    for v in values.values():
        missing |= np.isnan(v)
    raw_rows = np.flatnonzero(~missing)
    if not missing.any():
        return values, raw_rows, []

    rows = np.flatnonzero(missing)
    if raw_rows.size < 2:
        raise InputError(
            f'{import_map.source}: missing = "gap" leaves {raw_rows.size} row(s) of '
            f"{n}: every other row has a blank or non-finite cell; expected a log"
        )
    cols = [import_map.columns[c] for c, v in values.items() if np.isnan(v).any()]
    blocks = np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1)
    where = []
    for block in blocks:
        after = int(np.searchsorted(raw_rows, block[-1]))  # the log row that follows
        if after == 0:
            where.append("the log starts after them")
        elif after == raw_rows.size:
            where.append("the log ends before them")
        else:
            where.append(f"a gap before log row {after} (raw row {raw_rows[after]})")
    notes = [
        f'missing = "gap": raw rows {row_ranges(rows)} ({rows.size} row(s) with a blank or '
        f"non-finite cell in {', '.join(repr(c) for c in cols)}) left out, nothing filled: "
        + "; ".join(where)
        + "; the log's rows are the raw rows kept, renumbered from 0"
    ]
    return {k: v[~missing] for k, v in values.items()}, raw_rows, notes


def time_runs(
    t: np.ndarray, raw_rows: np.ndarray, import_map: ImportMap, src: str
) -> list[tuple[int, int]]:
    """The runs of a raw file: split where time restarts (the map's ``restart``).

    Parameters
    ----------
    t : numpy.ndarray
        s, the time of the rows kept, shape (n,).
    raw_rows : numpy.ndarray
        The raw row of each, shape (n,).
    import_map : ImportMap
    src : str
        The raw file's name, for messages.

    Returns
    -------
    list of (int, int)
        ``(start, stop)`` rows of ``t`` of each run (one run when time increases).

    Raises
    ------
    InputError
        Time that does not increase where it does not restart (a repeated or
        out-of-order time; the row named); time that restarts (steps back to an earlier
        value, 0 or not, and runs on from there: :func:`airbearing.io.log.restarts_at`;
        each run increasing and of at least 2 rows) while the map says
        ``restart = "error"``: the rows where it restarts and the fix.
    """

    header = import_map.columns["t"]
    back = np.flatnonzero(~(np.diff(t) > 0)) + 1
    starts, start = [0], 0
    for i in back.tolist():
        if restarts_at(t, i, start):
            starts.append(i)
            start = i
            continue
        rows = raw_rows[back]
        more = f"; {rows.size} such rows: {row_ranges(rows)}" if rows.size > 1 else ""
        raise InputError(
            f"{src}: row {raw_rows[i]}, column {header!r}: time must be strictly increasing, "
            f"but t = {t[i]:.6g} s follows t = {t[i - 1]:.6g} s of row {raw_rows[i - 1]}{more}"
        )
    if len(starts) > 1 and t.size - starts[-1] < 2:
        i = starts[-1]
        raise InputError(
            f"{src}: row {raw_rows[i]}, column {header!r}: time must be strictly increasing, "
            f"but t = {t[i]:.6g} s follows t = {t[i - 1]:.6g} s of row {raw_rows[i - 1]} "
            "(the last row)"
        )
    stops = [*starts[1:], int(t.size)]
    if len(starts) > 1 and import_map.restart != "split":
        at = ", ".join(str(raw_rows[i]) for i in starts[1:])
        first = starts[1]
        where = f" in {import_map.source}" if import_map.source else ""
        raise InputError(
            f"{src}: column {header!r}: time restarts at row {raw_rows[first]} (t = "
            f"{t[first]:.6g} s after {t[first - 1]:.6g} s): {_count(len(starts))} runs in one "
            f"file, split at row{'s' if len(starts) > 2 else ''} {at}; set restart = "
            f'"split"{where} to import one log per run (-o LOG writes LOG-run1, LOG-run2, ...), '
            "or cut the file there"
        )
    return list(zip(starts, stops, strict=True))


def _count(n: int) -> str:
    return {2: "two", 3: "three", 4: "four"}.get(n, str(n))


def _unwrap_note(shift: np.ndarray, raw_rows: np.ndarray, import_map: ImportMap) -> list[str]:
    """A note when the import unwrapped the yaw (FORMATS.md: it always does): where."""

    jumps = np.flatnonzero(np.diff(np.round(shift / (2.0 * np.pi))) != 0) + 1
    if not jumps.size:
        return []
    shown = row_ranges(raw_rows[jumps][:10]) + (" ..." if jumps.size > 10 else "")
    return [
        f"yaw ({import_map.columns['yaw']!r}) unwrapped: {jumps.size} jump(s) of 2 pi "
        f"removed (at raw row(s) {shown}); a log's yaw is continuous"
    ]


def _as_import_map(import_map) -> ImportMap:
    """``import_map`` as an :class:`ImportMap` (itself, a TOML file or a dict), or InputError."""
    if isinstance(import_map, ImportMap):
        return import_map
    if isinstance(import_map, Mapping):
        return import_map_from_dict(import_map, "import_map")
    if isinstance(import_map, str | os.PathLike):
        return read_import_map(import_map)
    raise InputError(
        f"import_map={import_map!r:.60}: expected an ImportMap, an import map file path or a "
        "dict in its TOML layout"
    )


def import_log(
    raw: str | os.PathLike[str] | object,
    import_map: ImportMap | str | os.PathLike[str],
    testbed: Testbed | None = None,
) -> Log:
    """A lab's raw log as a :class:`~airbearing.io.log.Log` (:func:`import_log_with_notes`).

    Parameters
    ----------
    raw : path-like or pandas.DataFrame
        The lab's export (``.csv``, with a byte-order mark, tab or semicolon separators
        allowed, or ``.parquet``).
    import_map : ImportMap, path-like or dict
        Its columns, units, frames and yaw unwrapping (FORMATS.md "Import map"): a map, its
        TOML file or a dict in the TOML layout.
    testbed : Testbed, str or path-like, optional
        A testbed, a built-in name or a testbed file. Validates the log against the
        testbed (columns, sampling) and finds its outliers.

    Returns
    -------
    Log
        In FORMATS.md columns and SI units; nothing filled, smoothed or resampled.

    Raises
    ------
    InputError
        A map key, column or unit the file or the map does not have (listing the valid
        ones), a non-numeric cell (row and column), time not increasing, ...

    Examples
    --------
    A motion-capture export with a millisecond clock and the yaw in degrees:

    >>> import pandas as pd
    >>> import airbearing as ab
    >>> raw = pd.DataFrame({"Time (ms)": [0.0, 100.0, 200.0],
    ...                     "Yaw (deg)": [179.0, -179.0, -177.0]})
    >>> mapping = {"columns": {"t": "Time (ms)", "yaw": "Yaw (deg)"},
    ...            "units": {"t": "ms", "yaw": "deg"}}
    >>> from airbearing.io.import_map import import_map_from_dict
    >>> log = ab.import_log(raw, import_map_from_dict(mapping))
    >>> log.t.tolist(), [round(float(y), 4) for y in log.data["yaw"]]  # s; rad, unwrapped
    ([0.0, 0.1, 0.2], [3.1241, 3.159, 3.194])
    """
    result = import_log_with_notes(raw, import_map, testbed)
    if len(result.logs) > 1:
        runs = ", ".join(f"{a}-{b - 1}" for a, b in result.runs)
        raise InputError(
            f"{result.log.source.split(' (run')[0]}: {len(result.logs)} runs (raw rows {runs}): "
            "import_log returns one log; use import_log_with_notes(...).logs"
        )
    return result.log
