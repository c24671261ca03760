"""The tables of a testbed file (FORMATS.md, "Testbed file (TOML)") as frozen dataclasses.

One class per table: :class:`Body`, :class:`Masses`, :class:`Magnetorquers`,
:class:`Wheels`, :class:`Field`, :class:`CMG`, :class:`Sensors`. Each validates and
normalises its values when built (:mod:`airbearing.io.testbed_tables`), so an invalid
table cannot exist. :class:`airbearing.io.testbed.Testbed` holds one of each and
re-exports them. Units are SI (s, m, kg, rad, rad/s, N m, A m^2, T).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from airbearing.io.testbed_tables import (
    _norm_body,
    _norm_cmg,
    _norm_field,
    _norm_magnetorquers,
    _norm_masses,
    _norm_sensors,
    _norm_wheels,
)
from airbearing.io.testbed_values import _MEMORY

__all__ = ["CMG", "Body", "Field", "Magnetorquers", "Masses", "Sensors", "Wheels"]

_IDENTITY3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _apply(obj: object, normalised: Mapping[str, Any]) -> None:
    for name, value in normalised.items():
        object.__setattr__(obj, name, value)


def _fields_of(obj: object) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}  # type: ignore[arg-type]


# ----------------------------------------------------------------------------
# the dataclasses


@dataclass(frozen=True)
class Body:
    """The rotating body: everything that floats on the air bearing.

    Parameters
    ----------
    dof : {1, 3}
        3: spherical bearing; 1: yaw-only bearing (rotation about body z).
    mass : float
        kg, everything that rotates, sliding masses included; > 0.
    inertia : float or 3x3 tuple of float
        kg m^2 about the centre of rotation (CR), body axes, sliding masses at
        rail zero. Symmetric positive definite 3x3; for ``dof = 1`` a single
        positive number (the yaw inertia) is accepted.
    cm_offset : 3-tuple of float
        m, CR -> centre of mass with the sliding masses at rail zero, body axes.
    torque_noise : float
        N m, 1-sigma white disturbance torque per sample and axis; >= 0.
    """

    dof: int
    mass: float
    inertia: float | tuple[tuple[float, ...], ...]
    cm_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    torque_noise: float = 0.0

    def __post_init__(self) -> None:
        _apply(self, _norm_body(_fields_of(self), _MEMORY))

    @property
    def inertia_matrix(self) -> np.ndarray:
        """Inertia about the CR, kg m^2, shape (3, 3); a scalar J gives diag(J, J, J)."""
        if isinstance(self.inertia, float):
            return np.eye(3) * self.inertia
        return np.array(self.inertia, dtype=float)

    @property
    def yaw_inertia(self) -> float:
        """Inertia about body z, kg m^2: the scalar inertia, or ``inertia[2][2]``."""
        if isinstance(self.inertia, float):
            return self.inertia
        return self.inertia[2][2]

    @property
    def cm_offset_vec(self) -> np.ndarray:
        """CR -> CM offset, m, body axes, shape (3,)."""
        return np.array(self.cm_offset, dtype=float)


@dataclass(frozen=True)
class Masses:
    """Sliding masses on rails through the CR (kind ``"platform"`` only).

    Parameters
    ----------
    mass : 3-tuple of float
        kg, one slider mass per rail; each > 0.
    axes : 3x3 tuple of float
        Rail unit vectors in body axes, one per row (norm within 1e-6 of 1;
        never normalised silently). Default: the body axes.
    travel : float
        m, each slider moves within [-travel, +travel]; > 0.
    step : float
        m, stepper resolution; >= 0.
    speed : float
        m/s, largest slider speed; > 0.
    backlash : float
        m, lost motion when a slider reverses; >= 0.
    gyro_vibration : float
        rad/s, 1-sigma white noise added per sample to each rate component when the
        steppers' summed speed over the sample before is ``speed``; it scales with the
        square root of that speed (each step shakes the platform once: noise power in
        proportion to the step rate); >= 0, default 0.
    accel_vibration : float
        -, 1-sigma white noise added per sample to each component of the measured
        gravity direction at the summed speed ``speed``; it scales in proportion to the
        speed (the reaction acceleration); >= 0, default 0.
    drive_torque_noise : float
        N m, 1-sigma white disturbance torque per sample and axis while a balancing law
        drives the steppers (none while the sliders are held); >= 0, default 0.
    """

    mass: tuple[float, float, float]
    axes: tuple[tuple[float, ...], ...] = _IDENTITY3
    travel: float = 0.037
    step: float = 2e-6
    speed: float = 0.005
    backlash: float = 0.0
    gyro_vibration: float = 0.0
    accel_vibration: float = 0.0
    drive_torque_noise: float = 0.0

    def __post_init__(self) -> None:
        _apply(self, _norm_masses(_fields_of(self), _MEMORY))

    @property
    def axes_matrix(self) -> np.ndarray:
        """Rail unit vectors, body axes, shape (3, 3), one rail per row."""
        return np.array(self.axes, dtype=float)

    @property
    def mass_vec(self) -> np.ndarray:
        """Slider masses, kg, shape (3,)."""
        return np.array(self.mass, dtype=float)


@dataclass(frozen=True)
class Magnetorquers:
    """Three magnetorquers along the body axes (kind ``"platform"`` only).

    Parameters
    ----------
    max_dipole : float
        A m^2, largest dipole per body axis; > 0.
    """

    max_dipole: float = 1.0

    def __post_init__(self) -> None:
        _apply(self, _norm_magnetorquers(_fields_of(self), _MEMORY))


@dataclass(frozen=True)
class Wheels:
    """Reaction wheels on the platform (kind ``"platform"`` only; FORMATS.md ``[wheels]``).

    Wheel ``i`` spins about the unit vector ``axes[i]`` (body axes) at the speed ``W_i``
    relative to the body. ``body.inertia`` includes the wheels as if locked.

    Parameters
    ----------
    axes : tuple of 3-tuples of float
        Spin-axis unit vectors, body axes, one per wheel (1 to 6 wheels; norm within
        1e-6 of 1, never normalised silently). For ``dof = 1`` each is ``(0, 0, +-1)``
        (checked by :class:`Testbed`).
    inertia : float or tuple of float
        kg m^2, each wheel about its spin axis; > 0. A number applies to every wheel;
        stored as one value per wheel.
    max_torque : float
        N m, largest motor torque of each wheel; > 0.
    max_speed : float
        rad/s, largest wheel speed relative to the body; > 0.
    command : {"torque", "speed"}
        What a logged command ``wc_i`` is: the motor torque (N m), or the wheel speed
        (rad/s) that the wheel's driver holds.
    speed_loop_tau : float or None
        s, time constant of the driver's speed loop; required (> 0) with
        ``command = "speed"``, None with ``"torque"``.
    speed_noise : float
        rad/s, 1-sigma white noise of each logged wheel speed; >= 0, default 0.
    speeds : tuple of float
        rad/s, wheel speeds at t = 0 when simulating, one per wheel (a number applies to
        every wheel); default 0.
    """

    axes: tuple[tuple[float, ...], ...]
    inertia: float | tuple[float, ...]
    max_torque: float
    max_speed: float
    command: str = "torque"
    speed_loop_tau: float | None = None
    speed_noise: float = 0.0
    speeds: float | tuple[float, ...] = ()

    def __post_init__(self) -> None:
        _apply(self, _norm_wheels(_fields_of(self), _MEMORY))

    @property
    def n(self) -> int:
        """Number of wheels."""
        return len(self.axes)

    @property
    def axes_matrix(self) -> np.ndarray:
        """Spin-axis unit vectors, body axes, shape (n, 3), one wheel per row."""
        return np.array(self.axes, dtype=float)

    @property
    def inertia_vec(self) -> np.ndarray:
        """Wheel inertias about their spin axes, kg m^2, shape (n,)."""
        return np.array(self.inertia, dtype=float)

    @property
    def speeds_vec(self) -> np.ndarray:
        """Wheel speeds at t = 0, rad/s, shape (n,)."""
        return np.array(self.speeds, dtype=float)


@dataclass(frozen=True)
class Field:
    """Helmholtz-cage magnetic field, constant in the lab frame.

    Parameters
    ----------
    lab : 3-tuple of float
        T, field in the lab frame (z up).
    """

    lab: tuple[float, float, float]

    def __post_init__(self) -> None:
        _apply(self, _norm_field(_fields_of(self), _MEMORY))

    @property
    def lab_vec(self) -> np.ndarray:
        """Field in the lab frame, T, shape (3,)."""
        return np.array(self.lab, dtype=float)


@dataclass(frozen=True)
class CMG:
    """Pyramid of four single-gimbal CMGs (kind ``"cmg"`` only; seed 001 eq. 12).

    Parameters
    ----------
    skew : float
        rad, pyramid skew angle beta, 0 < skew < pi/2.
    flywheel_inertia : float
        kg m^2, inertia of one flywheel about its spin axis; > 0.
    flywheel_speed : float
        rad/s, flywheel spin rate; > 0.
    max_gimbal_rate : float
        rad/s, largest gimbal rate per gimbal; > 0, ``math.inf`` for no limit.
    gimbal_angles : 4-tuple of float
        rad, gimbal angles at t = 0.
    """

    skew: float
    flywheel_inertia: float
    flywheel_speed: float
    max_gimbal_rate: float = math.inf
    gimbal_angles: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _apply(self, _norm_cmg(_fields_of(self), _MEMORY))

    @property
    def h0(self) -> float:
        """N m s, angular momentum of one flywheel: ``flywheel_inertia * flywheel_speed``."""
        return self.flywheel_inertia * self.flywheel_speed


@dataclass(frozen=True)
class Sensors:
    """Sampling and measurement noise.

    Parameters
    ----------
    rate : float
        Hz, sample and control rate; > 0.
    gyro_noise : float
        rad/s, 1-sigma white noise per sample on each rate component; >= 0.
    accel_noise : float
        -, 1-sigma white noise on each component of the measured gravity
        direction; >= 0.
    lowpass : float
        -, smoothing factor f_g of the gyro filter (seed 001 eq. 3),
        0 < lowpass <= 1; 1 means no filter.
    gyro : bool
        ``False``: no rate sensor (attitude from motion capture only); logs carry
        the attitude and no rate columns.
    attitude_noise : float
        rad, 1-sigma white noise per axis of the logged attitude (motion capture,
        star tracker); >= 0.
    """

    rate: float = 20.0
    gyro_noise: float = 0.0
    accel_noise: float = 0.0
    lowpass: float = 1.0
    gyro: bool = True
    attitude_noise: float = 0.0

    def __post_init__(self) -> None:
        _apply(self, _norm_sensors(_fields_of(self), _MEMORY))

    @property
    def dt(self) -> float:
        """s, sample period ``1 / rate``."""
        return 1.0 / self.rate
