"""Logs (FORMATS.md, "Log (CSV or Parquet)"): the :class:`Log` and its front doors.

A :class:`Log` holds one run's samples as a validated :class:`pandas.DataFrame`:
one row per sample, the columns of FORMATS.md (SI units) as float64, and any
other columns kept untouched. A log read from a file whose columns are all float64
without a missing cell holds them as NumPy arrays instead and builds the DataFrame
(``Log.data``) on first use: reading, checking and identifying such a log loads no
pandas (0.4-0.5 s of CPU of a new process).
:func:`read_log` reads one (:mod:`airbearing.io.log_read`:
CSV and Parquet by pyarrow), :func:`validate_log` checks a table
(:mod:`airbearing.io.log_validate`: nothing is filled or dropped; a bad cell, a missing
column, time that does not increase, a log that is all gaps or a non-unit quaternion
raises :class:`~airbearing.errors.InputError` naming the file, the row and the column),
:func:`write_log` writes one (:mod:`airbearing.io.log_write`, atomically). The column
rules every reader shares are in :mod:`airbearing.io.columns`; every name of those
modules a user needs is importable from here.

Rows are 0-based data-row indices (the header is not counted), the same in a raw
file, its imported log and every report; CSV messages add the line of the file.

A ``yaw`` written wrapped (within one turn, jumping by about 2 pi between samples) is
unwrapped on read and said (:mod:`airbearing.io.log_yaw`, ``data.attrs[YAW_UNWRAPPED]``):
the built-in CMG simulation and many loggers write it so, and no fit can use it wrapped.

Sampling (FORMATS.md, "Real logs are not perfect"), with ``T = 1 / sensors.rate``:

- an interval within ``[0.5 T, 1.5 T]`` is normal jitter: used with its logged times;
- an interval longer than ``1.5 T`` is a **gap**: it splits the log into segments
  (:func:`segments_of`); never an error;
- an interval shorter than ``0.5 T`` is **irregular** (a duplicated or late
  sample, a logger hiccup): used with its logged time like any other, not an
  error, and reported by ``airbearing log check``;
- a log in which no segment has at least 2 samples ("all gaps") is an error:
  nothing can be integrated, differentiated or fitted on it.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

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
from airbearing.io.log_checks import (  # noqa: F401 (re-exported: the log module's names)
    MEMORY_SOURCE,
    BadCellsError,
    column_list,
    quaternion_norm_hint,
    restarts_at,
)
from airbearing.io.log_read import log_format, read_table
from airbearing.io.log_write import log_bytes
from airbearing.io.log_yaw import YAW_UNWRAPPED, yaw_unwrapped_words
from airbearing.io.quality import LogQuality, assess
from airbearing.io.testbed import Testbed
from airbearing.io.testbed_write import _atomic_write_bytes

if TYPE_CHECKING:
    import pandas as pd

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
    "validate_log",  # noqa: F822 (module __getattr__: from log_validate on first use)
    "wheel_columns",
    "wheel_saturation",
    "write_log",
]

#: The names of :mod:`airbearing.io.log_validate` (a pandas table's checks) this module
#: gives, imported on first use (:func:`_tables`).
_TABLE_NAMES = ("numeric_column", "validate_log", "validated")


def _tables():
    """:mod:`airbearing.io.log_validate`, the checks of a pandas table, on first use."""
    # pandas: 0.4-0.5 s CPU to import, which a log of float64 columns read from a file
    # does not need (`airbearing identify` of a 10^4-row log: its whole budget is 1 s)
    from airbearing.io import log_validate

    return log_validate


def __getattr__(name: str):
    if name in _TABLE_NAMES:
        return getattr(_tables(), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
        if not log.has(column):
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
        self, data: pd.DataFrame, source: str = MEMORY_SOURCE, testbed: Testbed | None = None
    ) -> None:
        self.source = str(source)
        self.testbed = testbed
        self._frame = _tables().validated(data, self.source, testbed)
        self._arrays = None

    @classmethod
    def _from_validated(cls, data, source: str, testbed: Testbed | None) -> Log:
        """A Log of validated samples: a DataFrame, or ``(arrays, attrs)`` (float64 columns
        by name and the table's ``attrs``, :func:`~airbearing.io.log_read.read_table`)."""
        log = cls.__new__(cls)
        log.source, log.testbed = source, testbed
        if isinstance(data, tuple):
            log._frame, log._arrays = None, data
        else:
            log._frame, log._arrays = data, None
        return log

    @property
    def data(self) -> pd.DataFrame:
        """The samples as a :class:`pandas.DataFrame` (a log read from a file of float64
        columns holds arrays until this is asked for: no pandas otherwise)."""
        if self._frame is None:
            arrays, attrs = self._arrays
            self._frame = _tables().table_of(arrays, attrs)
            self._arrays = None
        return self._frame

    def _names(self):
        """The column names (a container: ``in`` is a hash lookup)."""
        return self._arrays[0].keys() if self._arrays is not None else self._frame.columns

    def _values(self, name: str) -> np.ndarray:
        """A column's values without a copy (read-only where they are Arrow's or the
        DataFrame's own)."""
        if self._arrays is not None:
            return self._arrays[0][name]
        return self._frame[name].to_numpy()

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
            cached = segments_of(np.asarray(self._values("t"), dtype=float), self.period)
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
            # the sign-continuous quaternions its checks shared (motion.signed_quaternions):
            # not kept with the log through a whole search (an hour of 50 Hz samples: 5.8 MB)
            self.__dict__.pop("_signed_quaternions", None)
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
            f"columns=[{column_list(self._names())}])"
        )

    def __len__(self) -> int:
        return self.n

    @property
    def n(self) -> int:
        """Number of samples (rows)."""
        return len(self._frame) if self._arrays is None else len(self._arrays[0]["t"])

    @property
    def t(self) -> np.ndarray:
        """Sample times, s, shape (n,)."""
        return np.array(self._values("t"), dtype=float)

    @property
    def dt(self) -> float:
        """Median sample interval, s."""
        return float(np.median(np.diff(np.asarray(self._values("t"), dtype=float))))

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
        present = self._names()
        return all(name in present for name in names)

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
        if not self.has(name):
            present = column_list(self._names())
            raise InputError(f"{self.source}: no column {name!r}; columns present: {present}")
        if self._arrays is not None:
            values = self._arrays[0][name]  # float64
            if not bad_mask(values).any():
                return values.copy()
        return _tables().numeric_column(self.data[name], name, self.source, None).copy()

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
            if name in LOG_COLUMNS and self.has(name) and self._values(name).dtype == float:
                out[:, i] = self._values(name)  # validated: finite float64
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
            present = self._names()
            n = sum(1 for c in family if c in present)
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
    return Log._from_validated(read_table(path, testbed, columns), str(path), testbed)


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
    kind = log_format(p)
    if isinstance(log, Log):
        data = log.data
    elif _tables().is_table(log):
        data = _tables().validated(log, str(path), None, unwrap_yaw=False)
    else:
        raise InputError(f"{path}: expected a Log or a pandas DataFrame, got {type(log).__name__}")
    return _atomic_write_bytes(p, log_bytes(data, kind))
