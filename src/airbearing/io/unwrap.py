"""Unwrapping a logged angle (a yaw written within one turn): :func:`unwrap`.

Used by the import map (:mod:`airbearing.io.import_map`, a raw file's yaw), the log's
validation (:mod:`airbearing.io.log_yaw`, a yaw written wrapped) and the log check
(:mod:`airbearing.io.quality_channels`); numpy only, so that none of them loads pandas
for it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["unwrap"]

_SEGMENT_BREAK = 1.5  # x the file's median interval (FORMATS.md)


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.mod(a + np.pi, 2.0 * np.pi) - np.pi


def unwrap(angle: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Unwrap an angle, each segment on its own, keeping the branch across isolated jumps.

    Parameters
    ----------
    angle : numpy.ndarray
        rad, shape (n,), e.g. a raw yaw in [-pi, pi).
    t : numpy.ndarray
        s, shape (n,), strictly increasing.

    Returns
    -------
    numpy.ndarray
        ``angle + 2 pi k`` (k integer per sample). A segment starts afresh (as
        logged) after an interval longer than 1.5 x the median interval. Within a
        segment each sample takes the branch nearest the previous sample, except
        after an isolated sample that jumps away and back (more than pi/3 from both
        neighbours while they are within pi/3 of each other): the sample after it
        takes the branch nearest the sample before it, so an occluded frame
        exported as 0 or a jump of more than pi and back does not change the branch.
    """
    y = np.asarray(angle, dtype=float)
    t = np.asarray(t, dtype=float)
    out = y.copy()
    if y.size < 2:
        return out
    dt = np.diff(t)
    breaks = np.flatnonzero(dt > _SEGMENT_BREAK * np.median(dt)) + 1
    for seg in np.split(np.arange(y.size), breaks):
        if seg.size < 2:
            continue
        s = y[seg]
        step = _wrap(np.diff(s))  # step[i]: s[i] -> s[i+1]
        inc = step.copy()
        if s.size >= 3:
            big = np.pi / 3
            skip = _wrap(s[2:] - s[:-2])  # s[j-1] -> s[j+1], j = 1..m-2
            spike = (np.abs(step[:-1]) > big) & (np.abs(step[1:]) > big) & (np.abs(skip) < big)
            j = np.flatnonzero(spike)  # sample j + 1 is the isolated jump
            inc[j + 1] = skip[j] - step[j]
        u = s[0] + np.concatenate([[0.0], np.cumsum(inc)])
        k = np.round((u - s) / (2.0 * np.pi))
        out[seg] = s + 2.0 * np.pi * k
    return out
