"""Peaks refined between the points of a frequency grid: every local maximum of the grid
within :data:`PEAK_FRACTION` of the largest is maximised between its two neighbours by a
golden-section search in ``ln w``, every candidate at once (:func:`golden_max`: one batched
evaluation a step, to :data:`PEAK_XTOL` in ``ln w``), so a lightly damped peak that falls
between grid points is not read low. The SISO margins refine ``|S|``, ``|T|`` and
``|S - 1/2|`` with it (:mod:`airbearing.design.margins_siso`), the multi-loop disk margin
the bound of ``mu`` (:mod:`airbearing.design.margins_multiloop`)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["PEAK_FRACTION", "PEAK_XTOL", "golden_max", "local_maxima"]

#: A local maximum of a peak's grid values at least this fraction of the largest is
#: refined between its neighbours: a lightly damped peak can rise that much between two
#: points of the grid.
PEAK_FRACTION = 0.8
#: The tolerance of a refined peak's frequency, in ln w.
PEAK_XTOL = 1e-7
_GOLDEN = (math.sqrt(5) - 1) / 2


def local_maxima(values: np.ndarray, at_least: float) -> set[int]:
    """Indices of the interior local maxima of ``values`` that reach ``at_least``."""
    inner = values[1:-1]
    local = np.nonzero((inner >= values[:-2]) & (inner >= values[2:]))[0] + 1
    return {int(k) for k in local[values[local] >= at_least]}


def golden_max(f, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Golden-section search for the maximum of ``f`` in ``[lo_k, hi_k]`` (ln w) of every
    bracket ``k`` at once: each step evaluates ``f`` (an array of frequencies, rad/s, to an
    array of values) at one new point of every bracket, until the brackets are narrower
    than ``2 PEAK_XTOL``. Returns the largest value evaluated in each bracket and its
    ln w (the brackets' ends are not evaluated)."""
    g = _GOLDEN
    a, b = np.array(lo, dtype=float), np.array(hi, dtype=float)
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = f(np.exp(c)), f(np.exp(d))
    top = np.maximum(fc, fd)
    x_top = np.where(fc >= fd, c, d)
    while np.max(b - a) > 2 * PEAK_XTOL:
        left = fc >= fd  # the maximum lies in [a, d], else in [c, b]
        a, b = np.where(left, a, c), np.where(left, d, b)
        new = np.where(left, b - g * (b - a), a + g * (b - a))
        f_new = f(np.exp(new))
        c, fc, d, fd = (
            np.where(left, new, d),
            np.where(left, f_new, fd),
            np.where(left, c, new),
            np.where(left, fc, f_new),
        )
        better = f_new > top
        top = np.where(better, f_new, top)
        x_top = np.where(better, new, x_top)
    return top, x_top
