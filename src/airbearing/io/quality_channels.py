"""The channel groups of a log that the outlier rule tests, and where its commands switch.

:func:`_groups` prepares each group's values and scale floor (the rates, the wheel
speeds, the attitude as a yaw unwrapped per segment or a quaternion with continuous
signs, and the inputs: gimbal angles minus their commanded rates' integral, sliders,
dipoles); :func:`_switch_rows` finds the rows near a switch of a logged command. The
rule is told in :mod:`airbearing.io.quality`'s docstring (step 1, step 4's floors,
"Inputs") and computed by :mod:`airbearing.io.quality_outliers`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from airbearing.io.columns import (
    _DIPOLES,
    _GIMBAL_RATES,
    _GIMBALS,
    _SLIDERS,
    WHEEL_COMMAND_COLUMNS,
)
from airbearing.io.motion import column_spans, signed_quaternions
from airbearing.io.quality_outliers import ABSOLUTE_FLOOR, _Group
from airbearing.io.testbed import Sensors, Testbed
from airbearing.io.unwrap import unwrap

if TYPE_CHECKING:
    from airbearing.io.log import Log

__all__ = ["SWITCH_RATIO"]

_RELATIVE_FLOOR = 1e-9  # scale floor relative to the channel's magnitude


def _groups(log: Log, testbed: Testbed | None, segments, switch: np.ndarray | None) -> list[_Group]:
    """The channel groups of a log; ``switch``: :func:`_switch_rows` on the same segments."""
    t = log.t
    groups = []
    sensors = testbed.sensors if testbed is not None else Sensors(gyro_noise=0.0)
    rates = log.rates()
    if rates is not None:
        cols = ("wx", "wy", "wz") if rates.shape[1] == 3 else ("wz",)
        mag = np.maximum(np.max(np.abs(rates), axis=0), 1.0)
        floor = np.maximum(max(sensors.gyro_noise, ABSOLUTE_FLOOR), _RELATIVE_FLOOR * mag)
        groups.append(_Group("rates", cols, rates, False, floor))
    speeds = log.wheel_speeds()
    if speeds is not None:  # measured like the rates, with the wheels' own noise
        wheels = testbed.wheels if testbed is not None else None
        cols = tuple(f"ws{i}" for i in range(1, speeds.shape[1] + 1))
        mag = np.maximum(np.max(np.abs(speeds), axis=0), 1.0)
        sigma = wheels.speed_noise if wheels is not None else 0.0
        floor = np.maximum(max(sigma, ABSOLUTE_FLOOR), _RELATIVE_FLOOR * mag)
        groups.append(_Group("wheel_speeds", cols, speeds, False, floor))
    dof = testbed.body.dof if testbed is not None else (3 if log.has("qw") else 1)
    use_yaw = dof == 1 and log.has("yaw")
    if use_yaw:
        yaw = log.column("yaw")
        for start, stop in segments:  # a logged yaw should be unwrapped; if not, this does
            yaw[start:stop] = unwrap(yaw[start:stop], t[start:stop])
        mag = max(float(np.max(np.abs(yaw))), 1.0)
        floor = np.array([max(sensors.attitude_noise, ABSOLUTE_FLOOR, _RELATIVE_FLOOR * mag)])
        groups.append(_Group("attitude", ("yaw",), yaw[:, None], False, floor, wrap=True))
    elif log.has("qw", "qx", "qy", "qz"):
        q = signed_quaternions(log, segments)
        floor = np.array([0.5 * max(sensors.attitude_noise, ABSOLUTE_FLOOR)])
        groups.append(_Group("attitude", ("qw", "qx", "qy", "qz"), q, True, floor))
    if switch is not None:
        for g in groups:  # (a quaternion's chi-square test takes no per-channel side)
            g.switch_rows = None if g.vector else switch
    groups += _input_groups(log, testbed, segments, t)
    return groups


#: A command switches where its change between two samples exceeds this many times its
#: median change (a reference step, a bang-bang switch, a stepper starting or stopping).
SWITCH_RATIO = 20.0


def _switch_rows(log: Log, segments, k: int) -> np.ndarray | None:
    """Rows within ``k`` of a switch of a logged command (io.quality doc, "Inputs"), or None.

    Commanded gimbal rates and dipoles switch where they step; slider positions where
    their speed does (a stepper starting or stopping). The platform's response has a kink
    there (its rate) or a change of curvature (its attitude), which a centred smooth fit
    cannot follow.
    """
    n = log.n
    out = np.zeros(n, dtype=bool)

    wc = tuple(c for c in WHEEL_COMMAND_COLUMNS if log.has(c))
    for cols, order in ((_GIMBAL_RATES, 1), (_DIPOLES, 1), (_SLIDERS, 2), (wc, 1)):
        if not cols:
            continue
        if not log.has(*cols) or _held(log, cols, segments, order):
            continue
        u = log.columns(cols)  # (a new float array, as np.stack of the columns)
        tiny = 1e-12 * np.max(np.abs(u), axis=0)  # once per log, not per segment
        for start, stop in segments:
            if stop - start <= order + 1:
                continue
            seg = u[start:stop]
            # a channel held within the segment (sliders parked) has no switch: its
            # differences are all 0, below any threshold (no diff, no median: the per-row
            # cost of a long log's parked sliders)
            moving = ~np.all(seg == seg[:1], axis=0)
            if not moving.any():
                continue
            du = np.abs(np.diff(seg[:, moving], order, axis=0))
            typical = np.median(du, axis=0)
            big = du > SWITCH_RATIO * np.maximum(typical, tiny[moving])
            for j in np.flatnonzero(big.any(axis=1)) + start + order:
                out[max(j - k, start) : min(j + k + 1, stop)] = True
    return out if out.any() else None


def _held(log: Log, cols, segments, order: int) -> bool:
    """True when each of ``cols`` (float64, read without a copy) holds one value within
    every segment :func:`_switch_rows` looks at: parked sliders, unlogged dipoles written
    as zeros. It finds no switch in them (every difference is 0), and the copy, the
    scales and the per-segment checks of the columns are not made (~0.03 s per 10^6-row
    log and group)."""
    for c in cols:
        v = log._values(c)
        if v.dtype != np.float64:
            return False  # as log.columns reads it: converted, or refused with its message
        for start, stop in segments:
            if stop - start > order + 1 and not np.all(v[start:stop] == v[start]):
                return False
    return True


def _changing(values: np.ndarray, segments) -> np.ndarray:
    """Per channel: does it change within some segment of at least 4 samples?"""
    out = np.zeros(values.shape[1], dtype=bool)
    for start, stop in segments:
        if stop - start >= 4:
            out |= column_spans(values[start:stop]) > 0
    return out


def _input_groups(log: Log, testbed: Testbed | None, segments, t: np.ndarray) -> list[_Group]:
    """Gimbal angles (minus the integral of their commanded rates), sliders and dipoles."""
    groups = []
    step = 0.0
    if testbed is not None and getattr(testbed, "masses", None) is not None:
        step = float(testbed.masses.step)  # whole steps (io.quality doc, "Inputs")
    for name, cols, floor in (
        ("gimbals", _GIMBALS, ABSOLUTE_FLOOR),
        ("sliders", _SLIDERS, max(step, ABSOLUTE_FLOOR)),
        ("dipoles", _DIPOLES, ABSOLUTE_FLOOR),
    ):
        if not log.has(*cols):
            continue
        x = log.columns(cols)
        if name == "gimbals":
            if not log.has(*_GIMBAL_RATES):
                continue  # io.quality doc: no commanded rates, no test
            dd = log.columns(_GIMBAL_RATES)
            for start, stop in segments:  # zero-order hold: dd_j acts over [t_j, t_j+1)
                steps = dd[start : stop - 1] * np.diff(t[start:stop])[:, None]
                x[start + 1 : stop] -= np.cumsum(steps, axis=0)
        use = _changing(x, segments)
        if not use.any():
            continue
        x = x[:, use]
        mag = np.maximum(np.max(np.abs(x), axis=0), 1.0)
        cols = tuple(c for c, u in zip(cols, use, strict=True) if u)
        groups.append(
            _Group(name, cols, x, False, np.maximum(floor, _RELATIVE_FLOOR * mag), sided=True)
        )
    return groups
