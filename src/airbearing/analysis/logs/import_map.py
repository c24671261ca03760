"""A lab's own log -> a log of FORMATS.md, by an import map (FORMATS.md, "Import map").

The map and the raw cells are read and checked by :mod:`airbearing.io.import_map`;
this module converts (units, lab axis up, quaternion direction, body axes, yaw
unwrapping) with the one quaternion module, :mod:`airbearing.models.quaternion`
(which is why it lives outside ``io``: ``io`` imports nothing from ``models``).

The import never drops, reorders, fills, smooths or resamples a row: row ``i`` of
the raw file is row ``i`` of the log.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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
from airbearing.io.log import LOG_COLUMNS, QUATERNION_NORM_TOL, RATE_COLUMNS, Log
from airbearing.io.testbed import Testbed
from airbearing.models import quaternion as quat

__all__ = ["ImportResult", "import_log", "import_log_with_notes", "lab_up_quaternion", "unwrap"]

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
    """

    log: Log
    notes: tuple[str, ...] = ()
    ignored: tuple[str, ...] = ()


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
    from scipy.spatial.transform import Rotation

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
    """
    import pandas as pd

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
        table = read_raw(Path(raw))  # type: ignore[arg-type]
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
    c = import_map.body_matrix

    if all(name in values for name in _QUATERNION):
        q = np.column_stack([values[name] for name in _QUATERNION])
        norm = np.linalg.norm(q, axis=1)
        off = np.abs(norm - 1.0) > QUATERNION_NORM_TOL
        if off.any():
            i = int(np.argmax(off))
            cols = ", ".join(repr(import_map.columns[n]) for n in _QUATERNION)
            raise InputError(
                f"{src}: row {i}, columns {cols}: expected a unit quaternion (norm within "
                f"{QUATERNION_NORM_TOL:g} of 1 is renormalised), got norm {norm[i]:.9g}"
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
    if "yaw" in values:
        values["yaw"] = unwrap(values["yaw"], values["t"])
    columns = {name: values[name] for name in LOG_COLUMNS if name in values}
    log = Log(pd.DataFrame(columns), source=src, testbed=testbed)
    return ImportResult(log, tuple(notes), skip)


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
    return import_log_with_notes(raw, import_map, testbed).log
