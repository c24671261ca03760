"""Does the gyro agree with the attitude logged beside it?

A log with both a gyro and an attitude (a yaw, a quaternion) holds the rate twice: the
gyro's, and the change of the attitude between samples. A dead gyro axis, a reversed one,
deg/s read as rad/s, a quaternion read in the wrong component order or frame, or a gyro
clipped at its full scale each make the two disagree grossly, and a fit on such a log
gives a confident wrong answer (an inertia 57 times off, a 1 s "sensor lag"). This module
compares them, per body axis:

- the least-squares slope ``b`` of the gyro's rate (the mean of the two samples around an
  interval) on the rate the attitude shows over that interval, with an intercept (a gyro
  bias, which the discrepancy can name, moves no slope), on every axis whose attitude
  rate changes clearly (its standard deviation at least :data:`MIN_MOTION` times the
  noise of that rate); the two agree when ``b`` is within :data:`AGREE` (0 for a dead axis,
  -1 for a reversed one, 57 or 0.017 for a unit mixed up; a lagging attitude filter stays
  near 1). On a steady spin (no change to fit a slope to) the two rates must differ by no
  more than a gyro bias can (:data:`MAX_BIAS`);
- a gyro reading stuck at its largest magnitude for :data:`FLAT_RUN` or more samples in a
  row while the attitude turns faster: saturated.

Intervals that touch an outlier row or span a gap are left out.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AGREE", "FLAT_RUN", "MAX_BIAS", "MIN_MOTION", "gyro_disagreement"]

#: The range of the gyro-on-attitude slope within which the two agree.
AGREE = (0.5, 2.0)
#: An axis is compared when its attitude rate's RMS is this many times its noise.
MIN_MOTION = 10.0
#: rad/s, the largest gyro bias (the discrepancy's physical range of ``gyro_bias``): on a
#: steady spin a difference up to it is a bias, which the discrepancy can name.
MAX_BIAS = 0.1
#: Consecutive samples at the largest magnitude that make a saturated gyro.
FLAT_RUN = 3
_AXES = ("x", "y", "z")


def _pairs(segments, usable: np.ndarray) -> np.ndarray:
    """Rows ``k`` whose interval ``(k, k + 1)`` lies in a segment, both rows usable."""
    inside = np.zeros(usable.size, dtype=bool)
    for a, b in segments:
        inside[a : b - 1] = True  # the last row of a segment starts no interval
    ok = inside[:-1] & usable[:-1] & usable[1:]
    return np.flatnonzero(ok)


def _increments(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``conj(q0) (x) q1`` (scalar first, Hamilton, FORMATS.md), the body-frame turn."""
    w0, v0 = q0[:, :1], -q0[:, 1:]
    w1, v1 = q1[:, :1], q1[:, 1:]
    out = np.empty((q0.shape[0], 4))
    # the sum over 3 components and the cross product by columns: the operations of
    # np.sum (in order) and np.cross, without their per-row overhead (~0.1 s per 10^6 rows)
    p = v0 * v1
    np.subtract(w0[:, 0] * w1[:, 0], p[:, 0] + p[:, 1] + p[:, 2], out=out[:, 0])
    v = w0 * v1 + w1 * v0
    for i, j, m in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):  # (v0 x v1)_i = v0_j v1_m - v0_m v1_j
        v[:, i] += v0[:, j] * v1[:, m] - v0[:, m] * v1[:, j]
    out[:, 1:] = v
    return out


def _ends(k: np.ndarray, n: int):
    """The first and second rows of the intervals ``k`` as indices: slices (views, no
    gathered copies of a long log's columns) when ``k`` is every interval ``0 .. n - 2``."""
    if k.size == n - 1:
        return slice(0, n - 1), slice(1, n)
    return k, k + 1


def _attitude_rates(log, k: np.ndarray) -> tuple[np.ndarray, tuple[str, ...]] | None:
    """Body rates the attitude shows over the intervals ``k`` (rad/s), and their axes."""
    t = log.t
    k0, k1 = _ends(k, t.size)
    h = t[k1] - t[k0]
    q = log.quaternions()
    if q is not None:
        inc = _increments(q[k0], q[k1])
        inc = inc * np.sign(inc[:, :1] + (inc[:, :1] == 0))  # the short way round
        return 2.0 * inc[:, 1:] / h[:, None], _AXES
    yaw = log.yaw()
    if yaw is None:
        return None
    d = np.angle(np.exp(1j * (yaw[k1] - yaw[k0])))  # wrapped: a logged yaw may jump 2 pi
    return (d / h)[:, None], ("z",)


def gyro_disagreement(log, segments, usable, attitude_noise: float) -> tuple[str, ...]:
    """Why the gyro and the attitude of ``log`` disagree, one sentence per axis (or none).

    Parameters
    ----------
    log : Log
        With a gyro (``wx..wz`` or ``wz``) and an attitude (``qw..qz`` or ``yaw``).
    segments : sequence of (int, int)
        Rows of each segment (stop exclusive).
    usable : ndarray of bool
        Rows that are not outliers.
    attitude_noise : float
        rad, the attitude's noise (the outlier rule's scale of the channel).

    Returns
    -------
    tuple of str
        Empty when they agree, or when nothing moves enough to tell.
    """
    w = log.rates()
    k = _pairs(segments, np.asarray(usable, dtype=bool))
    if w is None or k.size < 10:
        return ()
    att = _attitude_rates(log, k)
    if att is None:
        return ()
    w_att, axes = att
    cols = ("wx", "wy", "wz") if w.shape[1] == 3 else ("wz",)
    k0, k1 = _ends(k, w.shape[0])
    w_gyro = 0.5 * (w[k0] + w[k1])
    if w_gyro.shape[1] != w_att.shape[1]:
        w_gyro = w_gyro[:, -w_att.shape[1] :]
        cols = cols[-w_att.shape[1] :]
    t = log.t
    h = float(np.median(t[k1] - t[k0]))
    noise = np.sqrt(2.0) * max(float(attitude_noise), 1e-12) / h  # of one interval's rate
    out = []
    for j, axis in enumerate(axes):
        a, g = w_att[:, j], w_gyro[:, j]
        sat = _saturated(w[:, w.shape[1] - w_att.shape[1] + j], a, k, noise)
        if sat:  # (a clipped axis also reads a slope near 0: say what it is)
            out.append(f"gyro {cols[j]} {sat}")
            continue
        if np.std(a) >= MIN_MOTION * noise:  # the rate changes: the slope with an intercept
            ac, gc = a - a.mean(), g - g.mean()  # (a gyro bias, an effect, moves no slope)
            b = float(ac @ gc / (ac @ ac))
        elif np.sqrt(np.mean(a**2)) >= MIN_MOTION * noise:  # a steady spin: no intercept,
            b = float(a @ g / (a @ a))  # but a difference a gyro bias can make is no error
            if abs(float(np.mean(g - a))) <= MAX_BIAS:
                b = 1.0
        else:
            continue
        if not AGREE[0] <= b <= AGREE[1]:
            out.append(
                f"gyro {cols[j]} reads {b:.3g} x the rate the attitude shows about {axis} "
                "(near 0: a dead axis; near -1: a reversed one; near 57 or 0.017: deg/s and "
                "rad/s mixed up; else the attitude's component order or frame): fix the log "
                "or its import map"
            )
    return tuple(out)


def _saturated(w: np.ndarray, a: np.ndarray, k: np.ndarray, noise: float) -> str:
    """Where a gyro column sits at its largest magnitude while the attitude turns faster."""
    top = float(np.max(np.abs(w)))
    if top == 0:
        return ""
    at = np.abs(w) == top
    edges = np.diff(np.concatenate([[0], at.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    long = stops - starts >= FLAT_RUN
    # the attitude's rate over each run's intervals (k: the intervals compared)
    faster = []
    for s, e in zip(starts[long], stops[long], strict=True):
        inside = (k >= s) & (k < e - 1)
        if inside.any() and np.mean(np.abs(a[inside])) > top + 3 * noise:
            faster.append((int(s), int(e)))
    if not faster:
        return ""
    n = sum(e - s for s, e in faster)
    return (
        f"sits at its largest reading {top:.4g} rad/s for {n} samples (first rows "
        f"{faster[0][0]}-{faster[0][1] - 1}) while the attitude turns faster: saturated "
        "(the rate there is unknown)"
    )
