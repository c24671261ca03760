"""The columns of a log and the small rules every reader of one shares (FORMATS.md, "Log
(CSV or Parquet)"): the column names and groups, what a log of a testbed must hold, where
gaps split it into segments (:func:`segments_of`), which cells are unusable
(:func:`bad_mask`), rows and time stamps as text.

Below :mod:`airbearing.io.log` (the :class:`~airbearing.io.log.Log`; its files are read,
validated and written by :mod:`~airbearing.io.log_read`, :mod:`~airbearing.io.log_validate`
and :mod:`~airbearing.io.log_write`) and the checks
that read a log (:mod:`airbearing.io.quality`, :mod:`airbearing.io.motion`,
:mod:`airbearing.io.discontinuity`, :mod:`airbearing.io.import_map`), so that these import
each other one way only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from airbearing.io.testbed import Testbed

__all__ = [
    "COLUMN_GROUPS",
    "GAP_FACTORS",
    "LOG_COLUMNS",
    "MIN_SEGMENT_ROWS",
    "OVERFLOW_LIMIT",
    "QUATERNION_NORM_TOL",
    "RATE_COLUMNS",
    "RATE_MISMATCH_FACTOR",
    "REQUIRED_COLUMNS",
    "WHEEL_COMMAND_COLUMNS",
    "WHEEL_SPEED_COLUMNS",
    "bad_mask",
    "row_ranges",
    "segments_of",
    "time_text",
    "wheel_columns",
]

_QUATERNION = ("qw", "qx", "qy", "qz")
_RATES = ("wx", "wy", "wz")
_SLIDERS = ("s1", "s2", "s3")
_DIPOLES = ("mx", "my", "mz")
_FIELDS = ("bx", "by", "bz")
_GIMBALS = ("d1", "d2", "d3", "d4")
_GIMBAL_RATES = ("dd1", "dd2", "dd3", "dd4")
_MAX_WHEELS = 6  # FORMATS.md: 1 to 6 rows of wheels.axes
#: Measured wheel speeds ``ws1 .. ws6`` (rad/s, relative to the body); a log has
#: ``ws1 .. wsn`` for the n wheels of its testbed.
WHEEL_SPEED_COLUMNS: tuple[str, ...] = tuple(f"ws{i}" for i in range(1, _MAX_WHEELS + 1))
#: Wheel commands ``wc1 .. wc6`` (N m, or rad/s for speed-commanded wheels).
WHEEL_COMMAND_COLUMNS: tuple[str, ...] = tuple(f"wc{i}" for i in range(1, _MAX_WHEELS + 1))

#: Every column that FORMATS.md defines (all numeric, SI units).
LOG_COLUMNS: tuple[str, ...] = (
    "t",
    *_QUATERNION,
    "yaw",
    *_RATES,
    *_SLIDERS,
    *_DIPOLES,
    *_FIELDS,
    *_GIMBALS,
    *_GIMBAL_RATES,
    "yaw_ref",
    *WHEEL_SPEED_COLUMNS,
    *WHEEL_COMMAND_COLUMNS,
)
#: The measured angular-rate columns (rad/s, body axes).
RATE_COLUMNS: tuple[str, ...] = _RATES
#: Columns that come together: if one of a group is present, all must be.
COLUMN_GROUPS: tuple[tuple[str, ...], ...] = (
    _QUATERNION,
    _SLIDERS,
    _DIPOLES,
    _FIELDS,
    _GIMBALS,
    _GIMBAL_RATES,
)
#: Largest magnitude a log cell may have, on every column (SI units). The fits square
#: residuals, multiply up to three values (quaternion and inertia products) and sum
#: over up to 1e8 samples: with |x| <= 1e100, 1e8 * (1e100)**3 = 1e308 stays below the
#: largest float64 (1.8e308), so no use of a value overflows. No physical quantity of a
#: log (rad, rad/s, m, A m^2, T, s) comes anywhere near it: a larger value is a logger
#: fault, refused like a non-finite one.
OVERFLOW_LIMIT = 1e100
#: Largest allowed ``abs(norm(q) - 1)`` of a logged quaternion.
QUATERNION_NORM_TOL = 1e-3
#: Multiples of ``1 / sensors.rate``: an interval below the first is irregular
#: (used, reported), above the second is a gap (splits the log into segments).
GAP_FACTORS = (0.5, 1.5)
#: A segment needs this many samples to give a rate or a fit; a log without one
#: such segment is "all gaps" (an error).
MIN_SEGMENT_ROWS = 2


def REQUIRED_COLUMNS(testbed: Testbed | None = None) -> list[str]:  # noqa: N802 (contract name)
    """Columns a log of ``testbed`` must have.

    Parameters
    ----------
    testbed : Testbed or None
        Without a testbed only ``t`` is required.

    Returns
    -------
    list of str
        ``t``; the attitude: for dof 3 the quaternion ``qw, qx, qy, qz``, for
        dof 1 ``yaw`` (or the quaternion, see Notes); the rates when
        ``sensors.gyro`` is true (``wx, wy, wz`` for dof 3, ``wz`` for dof 1),
        none when it is false (motion capture); the sliders ``s1, s2, s3`` for
        kind ``"platform"`` with ``[masses]`` (none for a passive platform);
        the gimbal angles ``d1 .. d4`` for kind ``"cmg"``; the wheel speeds
        ``ws1 .. wsn`` with ``[wheels]`` (the commands ``wc1 .. wcn`` are optional:
        all or none).

    Notes
    -----
    For dof 1 the quaternion ``qw, qx, qy, qz`` is accepted in place of
    ``yaw`` (FORMATS.md); the list names ``yaw``, the form a writer should
    produce.
    """
    columns = ["t"]
    if testbed is None:
        return columns
    gyro = testbed.sensors.gyro
    if testbed.body.dof == 3:
        columns += [*_QUATERNION, *(_RATES if gyro else ())]
    else:
        columns += [*(("wz",) if gyro else ()), "yaw"]
    if testbed.kind == "platform":
        columns += list(_SLIDERS if testbed.masses is not None else ())
    else:
        columns += list(_GIMBALS)
    if testbed.wheels is not None:
        columns += list(wheel_columns(testbed.wheels.n)[0])
    return columns


def wheel_columns(n: int) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The log columns of ``n`` wheels: ``(ws1 .. wsn, wc1 .. wcn)``."""
    return WHEEL_SPEED_COLUMNS[:n], WHEEL_COMMAND_COLUMNS[:n]


def segments_of(t: np.ndarray, period: float) -> tuple[tuple[int, int], ...]:
    """Split sample times into segments at gaps.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, s, strictly increasing, shape (n,).
    period : float
        Nominal sample interval, s (``1 / sensors.rate``; the import map uses the
        file's median interval). An interval longer than ``1.5 * period`` is a gap.

    Returns
    -------
    tuple of (int, int)
        ``(start, stop)`` row ranges (0-based, stop exclusive) covering every
        row in order; a gap lies between ``stop - 1`` of one and ``start`` of the
        next. One-sample segments are kept (they are rows of the log).
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return ()
    breaks = np.flatnonzero(np.diff(t) > GAP_FACTORS[1] * period) + 1
    edges = [0, *breaks.tolist(), int(t.size)]
    return tuple((edges[i], edges[i + 1]) for i in range(len(edges) - 1))


def row_ranges(rows: Sequence[int]) -> str:
    """Rows as runs, ``500-519, 530`` (sorted, 0-based)."""
    rows = sorted(int(r) for r in rows)
    runs: list[list[int]] = []
    for r in rows:
        if runs and r == runs[-1][1] + 1:
            runs[-1][1] = r
        else:
            runs.append([r, r])
    return ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs)


def bad_mask(values: np.ndarray) -> np.ndarray:
    """Cells that cannot be used: not finite, or of magnitude above :data:`OVERFLOW_LIMIT`."""
    with np.errstate(invalid="ignore"):
        return ~(np.abs(values) <= OVERFLOW_LIMIT)  # NaN compares False: bad too


#: The median sample interval of a log must lie within this factor of ``1 / sensors.rate``
#: either way (:func:`_check_rate`).
RATE_MISMATCH_FACTOR = 1.5


def time_text(t: float, period: float) -> str:
    """A time stamp as text that tells samples apart: ``12.35``, ``1700000012.35``.

    Logs timed from an epoch (1.7e9 s) read as ``1.7e+09`` with six significant digits, the
    same at both ends of the log; from 1e5 s on the stamp is written in fixed point with
    the decimals that resolve ``period`` (s, the sample interval).
    """
    if abs(t) < 1e5 or not (period > 0 and math.isfinite(period)):
        return f"{t:.6g}"
    return f"{t:.{max(0, math.ceil(-math.log10(period)))}f}"
