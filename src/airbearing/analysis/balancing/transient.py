"""The seed-000 tilt loop linearised about level: integral time constant and settling time.

Steady state. The seed's metrics are over the last third of a 300 s run, which is steady
only if the tilt transient has settled by then. :func:`settling_time` gives that time from
the linearised loop and the run's start: from the rest position with the offset removed,
the P and D terms bring the platform level (117 s on platform-3dof); an offset that stays
needs the integral pole too, whose time constant is about ``(K_p + k_g) / (K_d K_i)``
(``k_g = -m |g| r_z``, the pendulum stiffness; :func:`integral_time_constant`), 210 s on
platform-3dof, and then 300 s is not steady. The comparison says so (``steady``) and
``--sweep duration=...`` shows where the steady state starts.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from airbearing.io.testbed import Testbed

__all__ = ["STEADY_TRANSIENT", "integral_time_constant", "settling_time", "steady_state"]

#: Fraction of its peak within which the tilt transient counts as settled: 5 %, the usual
#: settling criterion (three time constants of a first-order decay).
STEADY_TRANSIENT = 0.05


def _tilt_loops(testbed: Testbed, gains, vertical_offset: float) -> list[tuple]:
    """``(A, B)`` of the seed-000 tilt loop about body x and about y, linearised about level.

    States ``(xi, theta, theta')``, ``xi`` the integral of the tilt ``theta``, input a
    torque ``tau``: seed 000 eq. 1 with eq. 3 gives ``J theta'' = -(K_p + k_g) theta -
    K_d theta' - K_d K_i xi + tau``, ``k_g = -m |g| r_z`` and ``J`` that axis's inertia.
    """
    J_cr = testbed.body.inertia_matrix
    k_g = -testbed.body.mass * testbed.gravity * vertical_offset
    return _loops((J_cr[0, 0], J_cr[1, 1]), gains, k_g)


def _loops(inertias, gains, k_g: float) -> list[tuple]:
    kp, kd, kdki = (float(v) for v in gains)
    return [
        (
            np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-kdki / J, -(kp + k_g) / J, -kd / J]]),
            np.array([[0.0], [0.0], [1.0 / J]]),
        )
        for J in inertias
    ]


def integral_time_constant(testbed: Testbed, gains, vertical_offset: float) -> float:
    """s, time constant of the slowest pole of the seed-000 tilt loop about level.

    The poles of :func:`_tilt_loops`, roots of ``J s^3 + K_d s^2 + (K_p + k_g) s + K_d K_i``;
    the slowest of the two axes (for the seed-000 gains on a pendulous platform the
    integral pole, about ``-K_d K_i / (K_p + k_g)``). ``inf`` if the loop is not stable.
    """
    loops = _tilt_loops(testbed, gains, vertical_offset)
    poles = np.concatenate([np.linalg.eigvals(A) for A, _ in loops])
    if np.any(poles.real >= 0):
        return math.inf
    return float(1.0 / np.min(-poles.real))


def settling_time(
    testbed: Testbed,
    gains,
    vertical_offset: float,
    *,
    start: str = "rest",
    offset_stays: bool = False,
) -> float:
    """s, time after which a seed-000 balancing run's tilt transient has settled.

    The tilt loop linearised about level (:func:`_tilt_loops`). A run excites it through
    its start: from the rest position ``theta(0) = theta_r``; an offset that stays is a
    constant torque, ``tau = k_g theta_r`` (what holds the platform there), or any ``tau``
    from level; an offset the law removes, none. Settled: ``|theta|`` stays within
    :data:`STEADY_TRANSIENT` of its peak (python-control's forced response), the later of
    the two axes; ``inf`` when the loop is unstable (also started level: the noise grows
    without bound), else 0 when nothing is excited (started level, offset removed).
    """
    J = testbed.body.inertia_matrix
    k_g = -testbed.body.mass * testbed.gravity * vertical_offset
    # a comparison runs the same loop many times: the forced response is cached by value
    return _settling_time(
        (float(J[0, 0]), float(J[1, 1])),
        tuple(float(g) for g in gains),
        float(k_g),
        start,
        bool(offset_stays),
    )


@lru_cache(maxsize=256)
def _settling_time(
    inertias: tuple, gains: tuple, k_g: float, start: str, offset_stays: bool
) -> float:
    import control  # python-control, only for the forced response

    kdki = gains[2]
    theta0 = 1.0 if start == "rest" else 0.0
    tau = (k_g * theta0 if start == "rest" else 1.0) if offset_stays else 0.0
    worst = 0.0
    for A, B in _loops(inertias, gains, k_g):
        C, x0 = np.array([[0.0, 1.0, 0.0]]), [0.0, theta0, 0.0]
        if kdki == 0.0:  # without an integral term xi does not act: drop it
            A, B, C, x0 = A[1:, 1:], B[1:], C[:, 1:], x0[1:]
        poles = np.linalg.eigvals(A)
        if np.any(poles.real >= 0):
            return math.inf
        t = np.linspace(0.0, 12.0 / np.min(-poles.real), 20001)
        sys = control.ss(A, B, C, 0.0)
        theta = np.abs(control.forced_response(sys, t, np.full_like(t, tau), x0).y[0])
        outside = np.nonzero(theta > STEADY_TRANSIENT * theta.max())[0]
        worst = max(worst, float(t[outside[-1] + 1]) if outside.size else 0.0)
    return worst


def steady_state(settling: float, duration: float) -> dict:
    """Whether the last third of a ``duration`` s run is past the transient that settles in
    ``settling`` s (:func:`settling_time`); steady needs ``T >= 1.5 settling``."""
    start = 2.0 * duration / 3.0
    return {
        "settling_time_s": settling,
        "last_third_starts_s": start,
        "steady": bool(settling <= start),
        "duration_for_steady_s": 1.5 * settling,
    }
