"""The attitude-only log a motion-capture system records of a simulated run.

A closed-loop run (:func:`~airbearing.analysis.simulation.scenarios.slew`) needs a rate
gyro: its loop feeds back the rate. A lab whose testbed logs only the attitude
(``sensors.gyro = false``: motion capture, a camera) still flies such a loop on its own
gyro; what it logs is the attitude the camera saw and no rate. Dropping the rate columns
of a gyro log does NOT give that log on a yaw-only (dof 1) rig: its ``yaw`` column is the
loop's own yaw, the integral of the gyro (FORMATS.md, "yaw ... often the integral of the
gyro"), whose error is a random walk of the gyro noise (about 5e-4 rad after 40 s of the
``rw-yaw`` gyro), not the camera's white noise. A gyro-less testbed read with such a log
sees coloured noise at tens of times the floor its differences suggest and names effects
that are not there (``inertia_error`` and ``yaw_imbalance`` on a null ``rw-yaw`` slew).
:func:`attitude_only` writes the camera's attitude instead: the true attitude with white
noise of the testbed's ``sensors.attitude_noise``. The loop's own estimates of the state
(``yaw_est``, the attitude estimate ``qe_*``, the low-passed rate ``G_*``) go with the rate
columns: they are the gyro read through the loop (``yaw_est`` is that same random walk,
``G_*`` the rate itself), which a camera's export does not hold and which would hand a
tool or a reader the gyro the testbed says the log lacks. The loop's commands (``Tc_*``,
``wsat``) stay, as a lab that films its loop also logs what the loop asked for.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.columns import RATE_COLUMNS
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed

__all__ = ["attitude_only"]

#: The gyro's columns: the rates and the gravity direction it measures with them.
_RATES = (*RATE_COLUMNS, "gx", "gy", "gz")
_QUAT = ("qw", "qx", "qy", "qz")
#: The loop's state estimates (airbearing.design.attitude.EXTRA_NAMES and
#: airbearing.design.wheels.WHEEL_EXTRA_NAMES): the gyro read through the loop.
_LOOP_ESTIMATES = ("yaw_est", "qe_w", "qe_x", "qe_y", "qe_z", "G_x", "G_y", "G_z")


def attitude_only(
    log: Log, *, attitude_noise: float | None = None, seed: int = 0
) -> tuple[Testbed, Log]:
    """A simulated gyro log as a motion-capture system logs the same run.

    Parameters
    ----------
    log : Log
        A simulated log (with its ``true_*`` state columns) and its testbed.
    attitude_noise : float, optional
        rad, 1-sigma white noise per axis of the camera's attitude; default the testbed's
        ``sensors.attitude_noise``.
    seed : int
        Seed of the attitude noise.

    Returns
    -------
    (Testbed, Log)
        The testbed with ``sensors.gyro = false`` and that attitude noise, and the log
        without rate (``wx wy wz``), gravity-direction (``gx gy gz``) or loop-estimate
        (``yaw_est``, ``qe_*``, ``G_*``: module doc) columns whose
        attitude (``yaw``, or ``qw qx qy qz`` turned on the body side by the small
        rotation ``exp(n)``, as :func:`~airbearing.analysis.simulation.simulate.add_noise`)
        is the true one plus that noise. Every other column (wheel speeds and commands,
        sliders, dipoles, the loop's commands ``Tc_*``, ``true_*``) is kept as it was.

    Raises
    ------
    InputError
        The log has no testbed or no true attitude (not a simulated log), or a negative
        or non-finite noise.
    """
    tb = log.testbed
    if tb is None:
        raise InputError(f"{log.source}: attitude_only needs the log's testbed")
    sig = tb.sensors.attitude_noise if attitude_noise is None else float(attitude_noise)
    if not (np.isfinite(sig) and sig >= 0):
        raise InputError(f"attitude_noise={attitude_noise}: expected a 1-sigma angle >= 0 in rad")
    gone = (*_RATES, *_LOOP_ESTIMATES)
    data = log.data.drop(columns=[c for c in gone if c in log.data.columns])
    rng = np.random.default_rng(seed)
    n = len(data)
    if tb.body.dof == 1:
        _need(log, ("true_yaw",))
        data["yaw"] = data["true_yaw"].to_numpy() + sig * rng.standard_normal(n)
    else:
        true = _need(log, tuple(f"true_{k}" for k in _QUAT))
        q = quat.qmul(data[true].to_numpy(), quat.qexp(sig * rng.standard_normal((n, 3))))
        for i, k in enumerate(_QUAT):
            data[k] = q[:, i]
    sensors = dataclasses.replace(tb.sensors, gyro=False, attitude_noise=sig)
    tb_att = tb.replace(sensors=sensors)
    return tb_att, Log(data, source=log.source, testbed=tb_att)


def _need(log: Log, cols: tuple[str, ...]) -> list[str]:
    missing = [c for c in cols if c not in log.data.columns]
    if missing:
        raise InputError(
            f"{log.source}: missing column '{missing[0]}': attitude_only needs a simulated log "
            "with its true attitude"
        )
    return list(cols)
