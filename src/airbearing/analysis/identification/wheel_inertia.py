"""Yaw inertia of a reaction-wheel testbed (dof 1) from momentum exchange with its wheels.

On a yaw bearing the total angular momentum about the vertical (FORMATS.md, reaction
wheels) is ``H_z = J_z w_z + sum_i Iw_i s_i W_i`` (``s_i = +-1`` the sign of wheel
``i``'s axis along body z, ``W_i`` its measured speed relative to the body, ``J_z`` the
inertia with the wheels locked). The motors and the wheels' own bearing friction are
internal: they move momentum between the wheels and the body and leave ``H_z`` alone, so
only the table's bearing friction changes it, ``dH_z/dt = -c w_z - f sign(w_z)``.
This is the balance the CMG identification fits with the cluster's momentum
(:mod:`.cmg_inertia`): with ``h_z = sum_i Iw_i s_i W_i`` from the logged ``ws`` columns
the same regression

    w_z(t_k) = alpha - (1/J_z) h_z(t_k) - (c/J_z) int w_z dt - (f/J_z) int sign(w_z) dt

fixes the absolute ``J_z``: the wheel's data-sheet inertia and its measured speed carry
the scale, which free motion alone cannot (no scale ambiguity). Its errors are the same
prewhitened HAC sandwich, never below the white-noise value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airbearing.analysis.identification.cmg_inertia import (
    FRICTION,
    CMGIdentification,
    fit_momentum_exchange,
    log_pieces,
)
from airbearing.analysis.identification.options import wheel_columns
from airbearing.errors import InputError
from airbearing.io.coerce import check_gyro_agrees, check_log_testbed
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed

__all__ = ["WheelIdentification", "identify_wheel_inertia", "wheel_columns"]


@dataclass(frozen=True, eq=False, repr=False)
class WheelIdentification(CMGIdentification):
    """Identified yaw inertia of a dof-1 reaction-wheel testbed (momentum exchange).

    The fields of :class:`~airbearing.analysis.identification.cmg_inertia.CMGIdentification`
    (``inertia`` J_z in kg m^2 with the wheels locked, ``std_inertia``, ``friction``,
    ``std_friction``, ``std_white`` ...); ``details["wheel_inertia"]`` lists the wheels'
    inertias (kg m^2) that fixed the scale.

    Examples
    --------
    >>> import airbearing as ab
    >>> found = ab.identify("rw-yaw", [log])  # doctest: +SKIP
    >>> found.inertia, found.std_inertia  # doctest: +SKIP
    """


def _wheel_momentum(testbed: Testbed, log: Log) -> np.ndarray:
    """``h_z = sum_i Iw_i s_i W_i`` of every row, N m s."""
    wh = testbed.wheels
    names = [f"ws{i}" for i in range(1, wh.n + 1)]
    missing = [c for c in names if not log.has(c)]
    if missing:
        raise InputError(
            f"{log.source}: missing {', '.join(missing)}: the inertia of a reaction-wheel "
            f"testbed is identified from the measured wheel speeds ws1..ws{wh.n} (rad/s)"
        )
    W = log.columns(names)
    return W @ (wh.inertia_vec * wh.axes_matrix[:, 2])


def _pieces(testbed: Testbed, logs):
    """Per usable piece ``(t, w_z, h_z)`` and per log its JSON entry (segments, outliers)."""

    def arrays(log):
        if not isinstance(log, Log):
            raise InputError(f"identify: expected Log objects, got {type(log).__name__}")
        check_log_testbed(testbed, log, "the testbed to identify")
        check_gyro_agrees(log)
        if not log.has("wz"):
            raise InputError(
                f"{log.source}: missing wz: the momentum exchange needs the yaw rate (rad/s)"
            )
        hz = _wheel_momentum(testbed, log)
        if np.ptp(hz) <= 0:
            raise InputError(
                f"{log.source}: the wheel speeds do not change: no momentum exchange to use "
                "(drive the wheels, e.g. a slew, to identify the inertia)"
            )
        return log.t, log.column("wz"), hz

    return log_pieces(testbed, logs, arrays)


def identify_wheel_inertia(
    testbed: Testbed, logs, *, friction: str | None = None
) -> WheelIdentification:
    """Yaw inertia J_z of a dof-1 reaction-wheel testbed from its logs (momentum exchange).

    Parameters
    ----------
    testbed : Testbed
        ``kind = "platform"``, ``dof = 1``, with ``[wheels]``: their inertias fix the scale.
    logs : list of Log
        Runs with the yaw rate ``wz`` and the measured wheel speeds ``ws1..wsn`` in which
        the wheels exchange momentum with the table (a slew, steps of the yaw).
    friction : {None, "viscous", "coulomb"}
        The table's bearing friction identified with J_z (FORMATS.md ``viscous_friction``
        N m s, ``coulomb_friction`` N m). The wheels' own friction is internal and needs
        no term.

    Returns
    -------
    WheelIdentification
        ``inertia`` (kg m^2, the wheels locked) with its honest ``std_inertia``.

    Raises
    ------
    InputError
        Not a dof-1 wheel testbed, missing ``wz`` or ``ws`` columns, wheels at constant
        speed (no exchange).
    SolverError
        When Clarabel fails.
    """
    if testbed.kind != "platform" or testbed.body.dof != 1 or testbed.wheels is None:
        raise InputError(
            f"{testbed.source}: wheel inertia identification needs a dof = 1 platform with "
            f"[wheels], got kind = {testbed.kind!r}, dof = {testbed.body.dof}"
            + ("" if testbed.wheels is not None else ", no [wheels]")
        )
    if friction not in FRICTION:
        raise InputError(f"friction={friction!r}: expected None, 'viscous' or 'coulomb'")
    logs = list(logs)
    if not logs:
        raise InputError("identify: expected at least one log, got none")
    pieces, entries = _pieces(testbed, logs)
    wh = testbed.wheels
    # the wheel-speed noise enters the residual through h_z / J_z
    h_noise = wh.speed_noise * np.linalg.norm(wh.inertia_vec * wh.axes_matrix[:, 2])
    sigma = float(np.hypot(testbed.sensors.gyro_noise, h_noise / testbed.body.yaw_inertia))
    fields = fit_momentum_exchange(testbed, pieces, entries, friction, sigma)
    iw = [float(v) for v in testbed.wheels.inertia_vec]
    fields["details"] = {
        "wheel_inertia": iw,
        "scale": (
            "J_z is in proportion to the wheels' spin-axis inertia taken from the testbed "
            f"file ({', '.join(f'{v:.4g}' for v in iw)} kg m^2): an error of x % there "
            "moves J_z by x %, and the +- does not include it"
        ),
        **fields["details"],
    }
    return WheelIdentification(**fields)
