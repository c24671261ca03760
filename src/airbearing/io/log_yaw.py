"""A logged yaw written wrapped (within one turn): found, unwrapped on read, and said.

The built-in CMG simulation and many loggers write ``yaw`` wrapped to [-pi, pi) or
[0, 2 pi); no fit can use it so. :func:`unwrap_wrapped_yaw` (called by the log's
validation, :mod:`airbearing.io.log_validate`) recognises such a yaw and unwraps it as the
import map does (:func:`airbearing.io.import_map.unwrap`); the rows where its branch changed
are kept in ``data.attrs[YAW_UNWRAPPED]`` for ``log check`` and the tools to say
(:func:`yaw_unwrapped_words`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from airbearing.io.columns import GAP_FACTORS, row_ranges
from airbearing.io.testbed import Testbed
from airbearing.io.unwrap import unwrap

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["YAW_UNWRAPPED", "unwrap_wrapped_yaw", "wrapped_yaw", "yaw_unwrapped_words"]

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


def unwrap_wrapped_yaw(out: pd.DataFrame, testbed: Testbed | None) -> None:
    """A logged ``yaw`` written wrapped is unwrapped on read, and said (in place).

    :func:`wrapped_yaw` on the table's ``yaw``: when it finds the yaw written wrapped, the
    column is replaced by the unwrapped yaw and the rows where its branch changes are kept
    in ``out.attrs[YAW_UNWRAPPED]`` for ``log check`` and the tools to say.

    Parameters
    ----------
    out : pandas.DataFrame
        A log's samples (``t`` increasing); its ``yaw`` (rad) is replaced when unwrapped.
    testbed : Testbed or None
        Its ``sensors.rate`` says what a gap is (without one: the median interval).
    """
    if "yaw" not in out.columns:
        return
    found = wrapped_yaw(out["yaw"].to_numpy(), out["t"].to_numpy(), testbed)
    if found is not None:
        out["yaw"] = found[0]
        out.attrs[YAW_UNWRAPPED] = found[1]


def wrapped_yaw(
    yaw: np.ndarray, t: np.ndarray, testbed: Testbed | None
) -> tuple[np.ndarray, list[int]] | None:
    """A logged yaw written wrapped, unwrapped: the new yaw and the rows where its branch
    changes; None when the yaw is not written wrapped.

    The signature of a wrapped yaw: it stays within one turn (its range is at most 2 pi),
    moves smoothly (median step below :data:`_SMOOTH_STEP`) and jumps by about a whole turn
    (more than pi, within pi/2 of 2 pi k) between two samples of a segment. Such a yaw is
    unwrapped as the import map does (:func:`airbearing.io.import_map.unwrap`: each segment
    on its own, an isolated jump keeping the branch). A glitch (a frame exported as 0) on a
    spinning yaw is not one: the yaw spans more than a turn.

    Parameters
    ----------
    yaw : numpy.ndarray
        rad, shape (n,), finite.
    t : numpy.ndarray
        s, shape (n,), increasing.
    testbed : Testbed or None
        Its ``sensors.rate`` says what a gap is (without one: the median interval).

    Returns
    -------
    (numpy.ndarray, list of int) or None
    """
    if len(yaw) < 3:
        return None
    if not float(np.ptp(yaw)) <= 2 * math.pi + 1e-9:
        return None
    period = testbed.sensors.dt if testbed is not None else float(np.median(np.diff(t)))
    step = np.diff(yaw)
    wrapped = np.abs(np.mod(step + math.pi, 2 * math.pi) - math.pi)
    inside = np.diff(t) <= GAP_FACTORS[1] * period
    jump = (np.abs(step) > _WRAP_STEP) & (wrapped < _WRAP_SLACK) & inside
    if not jump.any() or not np.median(wrapped[inside]) < _SMOOTH_STEP:
        return None
    new = unwrap(yaw, t)
    turns = np.round((new - yaw) / (2 * math.pi))
    rows = [int(r) for r in np.flatnonzero(np.diff(turns) != 0) + 1]
    if not rows:
        return None
    return new, rows


def yaw_unwrapped_words(rows: Sequence[int]) -> str:
    """The sentence that says a yaw was unwrapped on read.

    Parameters
    ----------
    rows : sequence of int
        The rows where the branch changed (``data.attrs[YAW_UNWRAPPED]``, 0-based data rows).

    Returns
    -------
    str
        The sentence, ``""`` for no rows.
    """
    if not rows:
        return ""
    shown = row_ranges(list(rows)[:10]) + (" ..." if len(rows) > 10 else "")
    return (
        f"yaw written wrapped (to one turn): unwrapped on read, {len(rows)} jump(s) of 2 pi "
        f"removed at row(s) {shown}; the file is unchanged (import raw files with 'airbearing "
        "log import', which writes the yaw unwrapped)"
    )
