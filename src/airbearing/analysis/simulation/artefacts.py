"""Artefacts of real logs, injected on purpose: jitter, gaps, glitches, finite-difference edges.

Real logs are not perfect (FORMATS.md, "Log"): clocks jitter, recordings stop for a
while, a packet is dropped and read as 0, a marker swaps, a frame is occluded, an
exporter differentiates the attitude and writes rate 0 at each segment's first
sample. These functions put such artefacts into sample times (before
:func:`~airbearing.analysis.simulation.on_times.simulate_on_times`) or into a log, and
say which rows they hit (0-based data rows, FORMATS.md), so a tool can be tested
against the answer and a lab can rehearse its analysis.

Typical use::

    t = sample_times(tb, 300.0)
    t = with_jitter(t, 0.2, seed=1)
    t, after_gap = with_gap(t, 150.0, 20.0)
    log = simulate_on_times(tb, t, initial_rate=4.0, effects={"aero_drag": 3.5e-5})
    log, first = with_first_sample_artefact(log)
    log, hit = with_glitches(log, [613], "yaw_offset")
"""

from __future__ import annotations

import numpy as np

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed

__all__ = [
    "GLITCH_KINDS",
    "sample_times",
    "segment_starts",
    "with_jitter",
    "with_gap",
    "with_glitches",
    "with_first_sample_artefact",
    "with_last_sample_artefact",
    "with_sign_flips",
]

#: Glitch kinds and what each writes at a hit row.
GLITCH_KINDS: dict[str, str] = {
    "rate_zero": "every rate column read as 0 (a dropped gyro packet)",
    "rate_spike": "one rate column off by `size` rad/s (default +20 gyro sigmas)",
    "quat_wrong_frame": "the quaternion written in a lab frame turned by `size` rad about lab x "
    "(default 90 deg: a y-up motion-capture frame taken for z-up)",
    "yaw_offset": "the attitude turned by `size` rad about lab z (default 8 deg: a marker swap)",
    "yaw_zero": "an occluded frame exported as zero attitude (yaw = 0, q = [1, 0, 0, 0])",
}
_RATES = ("wx", "wy", "wz")
_QUAT = ("qw", "qx", "qy", "qz")
#: Default sizes: rate spike in gyro sigmas, wrong frame and yaw offset in rad.
SPIKE_SIGMAS = 20.0
WRONG_FRAME_ANGLE = np.pi / 2
YAW_OFFSET = np.deg2rad(8.0)


def sample_times(testbed: Testbed, duration: float, t0: float = 0.0) -> np.ndarray:
    """Uniform sample times ``t0 + k / sensors.rate``, ``round(duration * rate)`` of them (s)."""
    n = int(round(duration * testbed.sensors.rate))
    if n < 2:
        raise InputError(f"duration {duration} s: expected at least 2 samples at the sensor rate")
    return t0 + np.arange(n) * testbed.sensors.dt


def _times(times) -> np.ndarray:
    t = np.asarray(times, dtype=float)
    if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise InputError("times: expected at least 2 finite, strictly increasing sample times (s)")
    return t


def with_jitter(times, fraction: float, seed: int = 0) -> np.ndarray:
    """Sample times of a jittering clock: each interval changes by at most ``fraction``.

    Each time but the first moves by ``e_k = fraction / 2 * U(-1, 1) * min(adjacent
    intervals)``, so the new interval ``dt_k + e_(k+1) - e_k`` lies within
    ``dt_k (1 +- fraction)`` and the times stay strictly increasing and on the same clock
    (no drift). FORMATS.md uses a jittered interval as logged when it is within +-50 %
    of ``1 / rate``.

    Parameters
    ----------
    times : array_like (N,)
        Strictly increasing times, s.
    fraction : float
        Largest relative change of an interval, ``0 <= fraction < 1``.
    seed : int
        Seed of the jitter.
    """
    t = _times(times)
    if not 0 <= fraction < 1:
        raise InputError(f"jitter fraction {fraction}: expected 0 <= fraction < 1")
    dt = np.diff(t)
    local = np.minimum(np.r_[dt[0], dt], np.r_[dt, dt[-1]])
    e = fraction / 2 * np.random.default_rng(seed).uniform(-1, 1, t.size) * local
    e[0] = 0.0  # the log starts when it starts
    return t + e


def with_gap(times, t_start: float, length: float) -> tuple[np.ndarray, int]:
    """Times with the samples in ``[t_start, t_start + length)`` removed (a recording gap).

    Parameters
    ----------
    times : array_like (N,)
        Strictly increasing times, s.
    t_start, length : float
        Start and length of the gap, s; at least one sample must remain on each side.

    Returns
    -------
    times : ndarray
        The remaining times (the motion continues during the gap: simulate on them).
    row : int
        0-based row, in the returned times, of the first sample after the gap (the start
        of a new segment when the gap is longer than 1.5 sample periods).
    """
    t = _times(times)
    if not length > 0:
        raise InputError(f"gap length {length}: expected a positive time in s")
    cut = (t >= t_start) & (t < t_start + length)
    if not cut.any():
        raise InputError(f"gap [{t_start}, {t_start + length}) s holds no sample of the times")
    if cut[0] or cut[-1]:
        raise InputError(
            f"gap [{t_start}, {t_start + length}) s reaches the first or last sample "
            f"([{t[0]}, {t[-1]}] s): a gap needs samples on both sides"
        )
    return t[~cut], int(np.argmax(cut))


def segment_starts(log: Log) -> tuple[int, ...]:
    """Rows that start a segment: row 0 and each row after an interval > 1.5 sample periods.

    The period is ``1 / sensors.rate`` of the log's testbed (FORMATS.md), else the median
    interval of the log.
    """
    return tuple(start for start, _ in log.segments)


def _rows(rows, n: int) -> tuple[int, ...]:
    out = []
    for r in np.atleast_1d(rows).tolist():
        if not isinstance(r, int) or isinstance(r, bool):
            raise InputError(f"rows: expected 0-based integer row indices, got {r!r}")
        if not 0 <= r < n:
            raise InputError(f"rows: row {r} is outside the log's rows 0..{n - 1}")
        out.append(r)
    if len(set(out)) != len(out):
        raise InputError(f"rows {out}: a row is listed twice")
    if not out:
        raise InputError("rows: expected at least one row")
    return tuple(sorted(out))


def _present(log: Log, names, kind: str) -> list[str]:
    have = [c for c in names if c in log.data.columns]
    if not have:
        raise InputError(
            f"{log.source}: {kind!r} needs the column(s) {', '.join(names)}, "
            "and the log has none of them"
        )
    return have


def _turn_attitude(data, rows, q_lab, yaw_angle: float | None) -> None:
    """Turn the logged attitude at ``rows`` by ``q_lab`` on the lab side (in place)."""
    if all(c in data.columns for c in _QUAT):
        q = data.loc[list(rows), list(_QUAT)].to_numpy()
        data.loc[list(rows), list(_QUAT)] = quat.qmul(q_lab, q)
    if yaw_angle is not None and "yaw" in data.columns:
        data.loc[list(rows), "yaw"] += yaw_angle


def with_glitches(
    log: Log,
    rows,
    kind: str,
    *,
    size: float | None = None,
    column: str | None = None,
) -> tuple[Log, tuple[int, ...]]:
    """The log with isolated glitches of ``kind`` at ``rows``; truth columns untouched.

    Parameters
    ----------
    log : Log
        A log (usually simulated: its ``true_*`` columns keep the truth).
    rows : int or sequence of int
        0-based data rows to hit.
    kind : str
        One of :data:`GLITCH_KINDS`: ``rate_zero``, ``rate_spike``, ``quat_wrong_frame``
        (needs ``qw..qz``), ``yaw_offset``, ``yaw_zero`` (on ``yaw`` and/or ``qw..qz``).
    size : float, optional
        ``rate_spike``: rad/s added (default 20 x ``sensors.gyro_noise``; required when
        that is 0); ``quat_wrong_frame``: rad (default pi/2); ``yaw_offset``: rad (default
        8 deg).
    column : str, optional
        ``rate_spike``: the rate column hit (default the last rate column, ``wz`` or the
        only one present).

    Returns
    -------
    log : Log
        A new, validated log (same source and testbed).
    rows : tuple of int
        The rows hit, sorted.
    """
    if kind not in GLITCH_KINDS:
        raise InputError(f"glitch kind {kind!r}: expected one of {', '.join(GLITCH_KINDS)}")
    if size is not None and kind in ("rate_zero", "yaw_zero"):
        raise InputError(f"glitch kind {kind!r} takes no size (it writes zeros)")
    if size is not None and not np.isfinite(size):
        raise InputError(f"glitch size {size}: expected a finite number")
    if column is not None and kind != "rate_spike":
        raise InputError(f"glitch kind {kind!r} takes no column (only rate_spike does)")
    hit = _rows(rows, log.n)
    data = log.data.copy()
    idx = list(hit)
    if kind == "rate_zero":
        data.loc[idx, _present(log, _RATES, kind)] = 0.0
    elif kind == "rate_spike":
        have = _present(log, _RATES, kind)
        col = have[-1] if column is None else column
        if col not in have:
            raise InputError(f"rate_spike column {col!r}: expected one of {', '.join(have)}")
        if size is None:
            sigma = log.testbed.sensors.gyro_noise if log.testbed is not None else 0.0
            if sigma <= 0:
                raise InputError(
                    "rate_spike: give size (rad/s); the log's testbed has no gyro_noise to "
                    "scale a default spike of 20 sigmas"
                )
            size = SPIKE_SIGMAS * sigma
        data.loc[idx, col] += size
    elif kind == "quat_wrong_frame":
        if not all(c in data.columns for c in _QUAT):
            raise InputError(
                f"{log.source}: quat_wrong_frame needs the columns qw, qx, qy, qz "
                "(a yaw-only log: use yaw_offset)"
            )
        angle = WRONG_FRAME_ANGLE if size is None else size
        _turn_attitude(data, hit, quat.from_axis_angle([1, 0, 0], angle), None)
    elif kind == "yaw_offset":
        _present(log, ("yaw", *_QUAT), kind)
        angle = YAW_OFFSET if size is None else size
        _turn_attitude(data, hit, quat.from_axis_angle([0, 0, 1], angle), angle)
    else:  # yaw_zero
        _present(log, ("yaw", *_QUAT), kind)
        if "yaw" in data.columns:
            data.loc[idx, "yaw"] = 0.0
        if all(c in data.columns for c in _QUAT):
            data.loc[idx, list(_QUAT)] = [1.0, 0.0, 0.0, 0.0]
    return Log(data, source=log.source, testbed=log.testbed), hit


def with_first_sample_artefact(log: Log) -> tuple[Log, tuple[int, ...]]:
    """Rate 0 at the first sample of each segment, as a finite-difference export writes it.

    An exporter that differentiates the attitude has no previous sample at a segment's
    start and writes 0 there. Segments follow FORMATS.md (:func:`segment_starts`).

    Returns
    -------
    log : Log
        A new, validated log; every rate column (``wx wy wz`` or ``wz``) is 0 at the rows.
    rows : tuple of int
        The rows hit (the first row of each segment).
    """
    have = _present(log, _RATES, "first_sample")
    rows = segment_starts(log)
    data = log.data.copy()
    data.loc[list(rows), have] = 0.0
    return Log(data, source=log.source, testbed=log.testbed), rows


def with_last_sample_artefact(log: Log) -> tuple[Log, tuple[int, ...]]:
    """Rate 0 at the last sample of each segment, as a central-difference export writes it.

    The twin of :func:`with_first_sample_artefact`: a central difference has no next
    sample at a segment's end.

    Returns
    -------
    log : Log
        A new, validated log; every rate column is 0 at the rows.
    rows : tuple of int
        The rows hit (the last row of each segment).
    """
    have = _present(log, _RATES, "last_sample")
    starts = segment_starts(log)
    rows = tuple(s - 1 for s in (*starts[1:], log.n))
    data = log.data.copy()
    data.loc[list(rows), have] = 0.0
    return Log(data, source=log.source, testbed=log.testbed), rows


def with_sign_flips(log: Log, rows=None) -> tuple[Log, tuple[int, ...]]:
    """The quaternion negated at ``rows``: the same attitude (FORMATS.md: ``q`` and ``-q``).

    Not a glitch: many exporters keep ``qw >= 0`` and so change sign as the attitude
    passes half a turn; a tool must not flag or fit those rows differently. ``rows``
    default: every row with ``qw < 0`` (the ``qw >= 0`` hemisphere an exporter writes).

    Returns
    -------
    log : Log
        A new, validated log.
    rows : tuple of int
        The rows negated.
    """
    if not all(c in log.data.columns for c in _QUAT):
        raise InputError(f"{log.source}: sign flips need the columns qw, qx, qy, qz")
    data = log.data.copy()
    if rows is None:
        hit = tuple(int(i) for i in np.flatnonzero(data["qw"].to_numpy() < 0))
    else:
        hit = _rows(rows, log.n)
    if hit:
        data.loc[list(hit), list(_QUAT)] *= -1.0
    return Log(data, source=log.source, testbed=log.testbed), hit
