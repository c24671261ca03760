"""Does a log show its sensors' noise, and does it show any motion at all?

Two cheap checks on the measured channels of a log (the rates when the testbed has a
gyro, the attitude: ``yaw`` or the quaternion), against the noise its testbed declares
(``sensors.gyro_noise``, ``sensors.attitude_noise``):

- **Still channels** (:func:`still_channels`): a channel whose sample-to-sample scatter is
  far below its declared noise is not the sensor the testbed describes: a frozen value
  (an exporter that held the last sample, a dead sensor), a noise-free simulated log, or
  the wrong testbed. A noisy channel that repeats one value for :data:`HELD_RUN` samples
  or more (an exporter that held the last sample through a dropout) is named with those
  rows. The scatter is ``1.4826 * median(|second difference|) / sqrt(6)``
  within segments: under white noise of ``sigma`` a second difference has standard
  deviation ``sqrt(6) sigma``, while a smooth motion adds only ``accel * dt^2``
  (4e-5 rad at 0.1 rad/s^2 and 50 Hz), so the scatter measures the noise. Reported, not
  an error.
- **No motion** (:func:`no_motion`): every measured channel stays within
  :data:`NO_MOTION_SIGMAS` declared noise scales over the log (its few most extreme
  samples aside, so an isolated glitch does not count as motion) and no logged input
  changes. Nothing then excites the dynamics: a fit can only say that the model
  "explains" a platform at rest. ``identify`` and ``discrepancy`` refuse such a log
  before any fitting.

Both read each channel once (sorting-free: ``numpy.partition``), so a 10^6-row log is
judged in well under a second.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from airbearing.io.columns import segments_of
from airbearing.io.local_fits import row_all
from airbearing.quaternion import continuous_signs

if TYPE_CHECKING:
    from airbearing.io.log import Log
    from airbearing.io.testbed import Testbed

__all__ = [
    "HELD_RUN",
    "NO_MOTION_SIGMAS",
    "column_spans",
    "STILL_RATIO",
    "no_motion",
    "signed_quaternions",
    "still_channels",
]

#: A channel whose scatter is below its declared noise divided by this is reported as still.
STILL_RATIO = 10.0
#: A channel moves when its span (:func:`_span`) exceeds this many declared noise scales.
#: White noise spans about 2 x 4.4 = 8.8 scales over 10^6 samples with the 5 most extreme
#: samples of each side set aside; a motion of 12 scales is one no noise makes.
NO_MOTION_SIGMAS = 12.0
#: rad or rad/s: the noise scale of a channel whose testbed declares none (quieter than
#: any real sensor, as :data:`airbearing.io.quality.ABSOLUTE_FLOOR`).
_FLOOR = 1e-7
#: Samples of one repeated value that a noisy channel never gives by chance.
HELD_RUN = 20
_EXTREMES = 5  # samples of each end of a channel's range set aside (isolated glitches)
_MAD_TO_SIGMA = 1.4826
_INPUTS = (
    ("s1", "s2", "s3"),
    ("mx", "my", "mz"),
    ("d1", "d2", "d3", "d4"),
    ("dd1", "dd2", "dd3", "dd4"),
    ("bx", "by", "bz"),
)


def signed_quaternions(log: Log, segments) -> np.ndarray:
    """``continuous_signs(log.quaternions(), segments)`` (read-only), computed once per log
    and segments: the outlier rule, the still-channel and the no-motion checks all take it
    (three passes over a 10^6-row log's quaternions, ~0.1 s each, were one)."""
    memo = log.__dict__.setdefault("_signed_quaternions", {})
    key = tuple((int(a), int(b)) for a, b in segments)
    q = memo.get(key)
    if q is None:
        q = continuous_signs(log.quaternions(), segments)
        q.flags.writeable = False
        memo[key] = q
    return q


def _channels(
    log: Log, testbed: Testbed | None, segments
) -> list[tuple[str, np.ndarray, float, str]]:
    """The measured channels: ``(name, values (n, c), declared noise, its key)``."""
    sensors = testbed.sensors if testbed is not None else None
    gyro = 0.0 if sensors is None else sensors.gyro_noise
    att = 0.0 if sensors is None else sensors.attitude_noise
    out = []
    rates = log.rates()
    if rates is not None:
        names = ("wx", "wy", "wz") if rates.shape[1] == 3 else ("wz",)
        for i, name in enumerate(names):
            out.append((name, rates[:, i : i + 1], gyro, "gyro_noise"))
    dof = testbed.body.dof if testbed is not None else (1 if log.has("yaw") else 3)
    if log.has("yaw") and (dof == 1 or not log.has("qw", "qx", "qy", "qz")):
        out.append(("yaw", log.column("yaw")[:, None], att, "attitude_noise"))
    elif log.has("qw", "qx", "qy", "qz"):
        q = signed_quaternions(log, segments)
        # sigma rad per axis moves the unit quaternion's components by about sigma / 2
        out.append(("quaternion", q, 0.5 * att, "attitude_noise"))
    return out


def _scatter(x: np.ndarray, segments) -> float:
    """Robust sample-to-sample scatter (module doc), pooled over segments and columns."""
    parts = [np.diff(x[a:b], 2, axis=0).ravel() for a, b in segments if b - a >= 3]
    if not parts:
        return float("nan")
    d = np.abs(np.concatenate(parts))
    return float(_MAD_TO_SIGMA * np.median(d) / np.sqrt(6.0))


def still_channels(log: Log, testbed: Testbed | None, segments) -> tuple[str, ...]:
    """Channels far quieter than the noise their testbed declares (module doc).

    Parameters
    ----------
    log : Log
    testbed : Testbed or None
        Without one (or a channel without declared noise) nothing is reported.
    segments : sequence of (int, int)
        Row ranges between gaps (stop exclusive).

    Returns
    -------
    tuple of str
        One sentence per still channel: its scatter, the declared noise, what it may be.
    """
    out = []
    for name, x, noise, key in _channels(log, testbed, segments):
        if noise <= 0:
            continue
        s = _scatter(x, segments)
        if not s < noise / STILL_RATIO:
            out += _held_runs(name, x, key)
            continue
        unit = "rad/s" if key == "gyro_noise" else "rad"
        declared = 2 * noise if name == "quaternion" else noise
        scale = 2 * s if name == "quaternion" else s
        same = float(np.mean(row_all(np.diff(x, axis=0) == 0))) if x.shape[0] > 1 else 0
        what = (
            f"the same value on {same:.0%} of consecutive samples: frozen (a held or dead sensor?)"
            if same >= 0.5
            else "noise-free (a simulated or smoothed log? the wrong testbed?)"
        )
        out.append(
            f"{name} scatters by {scale:.3g} {unit} from sample to sample, below 1/"
            f"{STILL_RATIO:g} of the testbed's sensors.{key} = {declared:.3g} {unit}: {what}"
        )
    return tuple(out)


def _held_runs(name: str, x: np.ndarray, key: str) -> list[str]:
    """Stretches of a noisy channel that repeat one value for :data:`HELD_RUN` samples or
    more (an exporter holding the last sample through a dropout): one sentence."""
    same = row_all(np.diff(x, axis=0) == 0)  # same[i]: row i + 1 repeats row i
    if same.sum() < HELD_RUN - 1:
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], same.astype(np.int8), [0]])))
    runs = [(a, b + 1) for a, b in zip(edges[::2], edges[1::2], strict=True)]  # rows a..b-1
    runs = [(a, b) for a, b in runs if b - a >= HELD_RUN]
    if not runs:
        return []
    shown = ", ".join(f"{a}-{b - 1}" for a, b in runs[:5]) + (" ..." if len(runs) > 5 else "")
    return [
        f"{name} holds one value over rows {shown} ({sum(b - a for a, b in runs)} samples) "
        f"although the testbed's sensors.{key} says it is noisy: a dropout exported as the "
        "last value? (those rows are not measurements; the fits use them)"
    ]


def column_spans(x: np.ndarray) -> np.ndarray:
    """``np.ptp(x, axis=0)`` of an ``(n, c)`` array, column by column: the same numbers
    (a maximum and a minimum are exact), 4 times faster on a C-ordered array of 10^6 rows
    (a reduction down axis 0 steps row by row)."""
    return np.array([np.ptp(x[:, j]) for j in range(x.shape[1])], dtype=x.dtype)


def _span(x: np.ndarray) -> float:
    """Largest range over the columns, the :data:`_EXTREMES` most extreme samples of each
    end set aside (fewer on a short log)."""
    n = x.shape[0]
    k = min(_EXTREMES, max((n - 2) // 4, 0))
    if k == 0:
        return float(np.max(np.ptp(x, axis=0)))
    lo = np.partition(x, k, axis=0)[k]
    hi = np.partition(x, n - 1 - k, axis=0)[n - 1 - k]
    return float(np.max(hi - lo))


def no_motion(log: Log, testbed: Testbed | None) -> str:
    """Why the log shows no motion, or ``""`` when it moves (module doc).

    Parameters
    ----------
    log : Log
    testbed : Testbed or None
        Its declared noise scales the spans (no testbed: the floor 1e-7).

    Returns
    -------
    str
        ``""`` when some measured channel moves beyond :data:`NO_MOTION_SIGMAS` noise
        scales or a logged input changes; else one sentence: each channel's span
        against its noise.
    """
    period = testbed.sensors.dt if testbed is not None else log.dt
    segments = segments_of(log.t, period)
    channels = _channels(log, testbed, segments)
    if not channels:
        return ""
    for cols in _INPUTS:
        if log.has(*cols) and np.any(column_spans(log.columns(list(cols))) > 0):
            return ""
    spans = []
    for name, x, noise, key in channels:
        scale = max(noise, _FLOOR)
        span = _span(x)
        if span > NO_MOTION_SIGMAS * scale:
            return ""
        unit = "rad/s" if key == "gyro_noise" else "rad"
        if name == "quaternion":
            span, scale = 2 * span, 2 * scale
        spans.append(f"{name} within {span:.3g} {unit} (sensors.{key} {scale:.3g} {unit})")
    return (
        f"the log shows no motion: {', '.join(spans)} over all {log.n} rows, within "
        f"{NO_MOTION_SIGMAS:g} x its noise, and no logged input changes: "
        "nothing excites the dynamics; log a run in which the platform moves"
    )
