"""Real balancing actuators as discrete CasADi blocks: stepper-driven sliders and magnetorquers.

Each block runs at the controller's sample rate inside the compiled closed loop and
carries its own state in the controller state ``c``.

Sliders (the ``[masses]`` keys of FORMATS.md)
    Per sample of length ``dt``, for each rail: the commanded position is clipped to
    the travel ``[-travel, +travel]``, optionally passed through a first-order lag of
    time constant ``lag`` (firmware smoothing; 0 = none), rounded to the stepper
    resolution ``step``, and the motor (the nut on the lead screw) moves towards it by
    at most ``speed * dt`` (a whole number of steps). The mass follows the motor with
    lost motion ``backlash`` (a play operator: the mass moves only when the motor
    pushes on one side of the gap; seed 000 Sec. 1 names backlash as the limit of
    mass-only balancing, seed 004 gives 0.02 mm). The position held over the sample
    is the midpoint of the mass's ramp (the mean of a constant-speed move).
Magnetorquers (``[magnetorquers] max_dipole``)
    Each coil saturates on its own: every body component of the commanded dipole is
    clipped to ``+-max_dipole`` (seed 000 Sec. 2: 1 A m^2 per coil).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing.errors import InputError

__all__ = ["SliderActuator", "MagnetorquerActuator"]


@dataclass(frozen=True)
class SliderActuator:
    """Three stepper-driven sliding masses with speed limit, steps, travel and backlash.

    Parameters
    ----------
    travel : float
        m, each slider moves within ``[-travel, +travel]``.
    step : float
        m, stepper resolution (0 = continuous).
    speed : float
        m/s, largest slider speed (``inf`` = reaches its target within one sample).
    backlash : float
        m, lost motion when a slider reverses (0 = none).
    lag : float
        s, time constant of a first-order lag on the command (0 = none).

    Notes
    -----
    State per rail: motor position ``p``, mass position ``s`` and (``lag > 0``) the
    lag filter ``f``; :meth:`state0` gives the state of sliders at rest.
    """

    travel: float
    step: float = 0.0
    speed: float = math.inf
    backlash: float = 0.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        for name, lo in (("travel", 0.0), ("speed", 0.0)):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and v > lo and not math.isnan(v)):
                raise InputError(f"slider {name} {v!r}: expected a number > {lo}")
        for name in ("step", "backlash", "lag"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise InputError(f"slider {name} {v!r}: expected a finite number >= 0")

    @classmethod
    def from_testbed(cls, testbed, *, ideal: bool = False, lag: float = 0.0) -> SliderActuator:
        """The sliders of ``testbed.masses``; ``ideal=True`` keeps only the travel limit."""
        m = testbed.masses
        if m is None:
            raise InputError(f"{testbed.source}: testbed '{testbed.name}' has no [masses] table")
        if ideal:
            return cls(travel=m.travel)
        return cls(travel=m.travel, step=m.step, speed=m.speed, backlash=m.backlash, lag=lag)

    @property
    def n_states(self) -> int:
        """Number of controller-state entries the block uses."""
        return 9 if self.lag > 0 else 6

    def state0(self, positions) -> np.ndarray:
        """State of sliders at rest at ``positions`` (m), backlash gap centred."""
        s = np.asarray(positions, dtype=float).reshape(3)
        if np.any(np.abs(s) > self.travel * (1 + 1e-12)):
            raise InputError(
                f"slider positions {s.tolist()} m: each must lie within +-{self.travel} m "
                "(masses.travel)"
            )
        parts = [s, s] + ([s] if self.lag > 0 else [])
        return np.concatenate(parts)

    def max_move(self, dt: float) -> float:
        """m, largest motor move in one sample: ``speed * dt`` rounded down to whole steps."""
        v = self.speed * dt
        if self.step > 0 and math.isfinite(v):
            n = math.floor(v / self.step + 1e-9)
            if n < 1:
                raise InputError(
                    f"slider speed {self.speed} m/s moves less than one step ({self.step} m) "
                    f"per sample of {dt} s: the sliders could never move"
                )
            return n * self.step
        return v

    def function(self, dt: float) -> ca.Function:
        """``(cmd[3], state) -> (s_held[3], state_next, motor[3])`` for a sample of ``dt`` s."""
        cmd = ca.SX.sym("s_cmd", 3)
        st = ca.SX.sym("slider_state", self.n_states)
        p, s = st[0:3], st[3:6]
        target = ca.fmin(ca.fmax(cmd, -self.travel), self.travel)  # travel limits
        parts_next = []
        if self.lag > 0:
            f = st[6:9]
            f_next = f + (1 - math.exp(-dt / self.lag)) * (target - f)
            target = f_next
        if self.step > 0:
            target = self.step * ca.floor(target / self.step + 0.5)  # stepper resolution
            limit = self.step * math.floor(self.travel / self.step + 1e-9)
            target = ca.fmin(ca.fmax(target, -limit), limit)
        move = self.max_move(dt)
        if math.isfinite(move):
            p_next = p + ca.fmin(ca.fmax(target - p, -move), move)  # speed limit
        else:
            p_next = target
        half = 0.5 * self.backlash
        s_next = ca.fmin(ca.fmax(s, p_next - half), p_next + half)  # backlash (play operator)
        held = 0.5 * (s + s_next)
        parts_next = [p_next, s_next] + ([f_next] if self.lag > 0 else [])
        return ca.Function(
            "sliders",
            [cmd, st],
            [held, ca.vertcat(*parts_next), p_next],
            ["s_cmd", "state"],
            ["s_held", "state_next", "motor"],
        )


@dataclass(frozen=True)
class MagnetorquerActuator:
    """Three orthogonal coils, each saturating at ``max_dipole`` (A m^2)."""

    max_dipole: float = math.inf

    def __post_init__(self) -> None:
        v = self.max_dipole
        if not (isinstance(v, int | float) and v > 0 and not math.isnan(v)):
            raise InputError(f"magnetorquers.max_dipole {v!r}: expected a number > 0 (A m^2)")

    @classmethod
    def from_testbed(cls, testbed, *, ideal: bool = False) -> MagnetorquerActuator:
        """The coils of ``testbed.magnetorquers``; error when the testbed has none."""
        if testbed.magnetorquers is None:
            raise InputError(
                f"{testbed.source}: testbed '{testbed.name}' has no [magnetorquers] table, "
                "but the method needs magnetorquers"
            )
        return cls() if ideal else cls(max_dipole=testbed.magnetorquers.max_dipole)

    def function(self) -> ca.Function:
        """``d_cmd[3] -> d[3]`` (A m^2, body axes), clipped per coil."""
        d = ca.SX.sym("d_cmd", 3)
        out = (
            d
            if math.isinf(self.max_dipole)
            else ca.fmin(ca.fmax(d, -self.max_dipole), self.max_dipole)
        )
        return ca.Function("magnetorquers", [d], [out], ["d_cmd"], ["d"])
