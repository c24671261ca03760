"""Testbed files (FORMATS.md, "Testbed file (TOML)"): read, validate, write.

A :class:`Testbed` is the nominal model of one air-bearing simulator plus the
named effects already known to act on it. It is a frozen dataclass whose
vectors and matrices are tuples of floats, so two testbeds compare equal when
their values are equal; numpy views are available as properties. Every
constructor validates its values, so an invalid Testbed cannot exist.

Units are SI throughout (s, m, kg, rad, rad/s, N m, A m^2, T). Angles are
radians inside; a ``_deg`` key of a file gives the same quantity in degrees.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from airbearing.errors import InputError
from airbearing.io.builtins import builtin_names, builtin_toml
from airbearing.io.output import write_temp
from airbearing.io.vocabulary import EFFECTS, EffectValue, validate_effect_value

__all__ = [
    "BUILTIN_TESTBEDS",
    "CMG",
    "DEFAULT_GRAVITY",
    "DEFAULT_SKEW_DEG",
    "KINDS",
    "Body",
    "Field",
    "Magnetorquers",
    "Masses",
    "Sensors",
    "Testbed",
    "Wheels",
    "WHEEL_COMMANDS",
    "load_testbed",
    "read_testbed",
    "testbed_from_dict",
    "testbed_to_dict",
    "write_testbed",
]

#: Names accepted by :func:`load_testbed` in place of a path (catalogue: io/builtins.py).
BUILTIN_TESTBEDS: tuple[str, ...] = builtin_names()
#: Values of the top-level ``kind`` key.
KINDS: tuple[str, ...] = ("platform", "cmg")
#: m/s^2, default of the top-level ``gravity`` key (FORMATS.md).
DEFAULT_GRAVITY = 9.81
#: deg, default CMG pyramid skew angle (seed 001 Table 6: beta = 54.73 deg).
DEFAULT_SKEW_DEG = 54.73

_MEMORY = "<memory>"
_DOFS = (1, 3)
_SYMMETRY_RTOL = 1e-9  # relative tolerance of the inertia symmetry check
_UNIT_NORM_TOL = 1e-6  # |norm - 1| allowed for a rail axis
_N_GIMBALS = 4
_IDENTITY3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
_MAX_WHEELS = 6
#: Values of ``wheels.command``: the logged command is a motor torque or a wheel speed.
WHEEL_COMMANDS: tuple[str, ...] = ("torque", "speed")
_DEG_SEARCH_ULPS = 8  # neighbours tried to find a degree value that reads back exactly


# ----------------------------------------------------------------------------
# value checks: each takes the value, the source (file) and the dotted key


def _is_number(value: object) -> bool:
    """True for int and float (numpy scalars included); booleans are not numbers."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def _fail(src: str, key: str, expected: str, got: object) -> InputError:
    shown = str(got).lower() if isinstance(got, bool) else repr(got)  # TOML's true/false
    return InputError(f"{src}: key '{key}': expected {expected}, got {shown}")


def _number(
    value: object,
    src: str,
    key: str,
    unit: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    allow_inf: bool = False,
) -> float:
    """A float from an int or float (not a bool), finite unless allowed, within bounds."""
    bounds = []
    if gt is not None:
        bounds.append(f"> {gt:g}")
    if ge is not None:
        bounds.append(f">= {ge:g}")
    if lt is not None:
        bounds.append(f"< {lt:g}")
    if le is not None:
        bounds.append(f"<= {le:g}")
    what = "a " + ("" if allow_inf else "finite ") + "number"
    if bounds:
        what += " " + " and ".join(bounds)
    if unit:
        what += f" ({unit})"
    if not _is_number(value):
        raise _fail(src, key, what, value)
    x = float(value)  # type: ignore[arg-type]
    if math.isnan(x) or (math.isinf(x) and not allow_inf):
        raise _fail(src, key, what, value)
    if (
        (gt is not None and not x > gt)
        or (ge is not None and not x >= ge)
        or (lt is not None and not x < lt)
        or (le is not None and not x <= le)
    ):
        raise _fail(src, key, what, value)
    return x


def _vector(value: object, n: int, src: str, key: str, unit: str) -> tuple[float, ...]:
    """A tuple of n finite floats."""
    what = f"a list of {n} finite numbers ({unit})"
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != n:
        raise _fail(src, key, what, value)
    out = []
    for v in value:
        if not _is_number(v) or not math.isfinite(float(v)):
            raise _fail(src, key, what, value)
        out.append(float(v))
    return tuple(out)


def _vector3(value: object, src: str, key: str, unit: str) -> tuple[float, float, float]:
    x, y, z = _vector(value, 3, src, key, unit)
    return (x, y, z)


def _matrix3(value: object, src: str, key: str, what: str) -> tuple[tuple[float, ...], ...]:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise _fail(src, key, what, value)
    rows = []
    for row in value:
        if isinstance(row, np.ndarray):
            row = row.tolist()
        if not isinstance(row, list | tuple) or len(row) != 3:
            raise _fail(src, key, what, value)
        if not all(_is_number(v) and math.isfinite(float(v)) for v in row):
            raise _fail(src, key, what, value)
        rows.append(tuple(float(v) for v in row))
    return tuple(rows)


def _inertia(value: object, dof: int, src: str, key: str) -> float | tuple[tuple[float, ...], ...]:
    """Scalar yaw inertia (dof 1 only) or a symmetric positive definite 3x3 matrix."""
    if _is_number(value):
        if dof != 1:
            raise _fail(
                src,
                key,
                "a symmetric 3x3 matrix (kg m^2) for dof = 3 (a single number is "
                "accepted only for dof = 1)",
                value,
            )
        return _number(value, src, key, "kg m^2", gt=0.0)
    what = "a symmetric positive definite 3x3 matrix (kg m^2)"
    if dof == 1:
        what = "a positive number or " + what
    matrix = _matrix3(value, src, key, what)
    m = np.array(matrix)
    scale = float(np.max(np.abs(m)))
    if float(np.max(np.abs(m - m.T))) > _SYMMETRY_RTOL * scale:
        raise _fail(src, key, "a symmetric 3x3 matrix (kg m^2)", value)
    eigenvalues = np.linalg.eigvalsh(0.5 * (m + m.T))
    if not np.all(eigenvalues > 0.0):
        raise InputError(
            f"{src}: key '{key}': expected a positive definite 3x3 matrix (kg m^2), "
            f"got {value!r} with eigenvalues {eigenvalues.tolist()!r}"
        )
    return matrix


def _integer_choice(value: object, choices: tuple[int, ...], src: str, key: str) -> int:
    what = "one of " + ", ".join(str(c) for c in choices)
    if isinstance(value, np.integer):
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool) or value not in choices:
        raise _fail(src, key, what, value)
    return value


# ----------------------------------------------------------------------------
# normalisers: raw field values -> validated field values (same keys)


def _norm_body(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    dof = _integer_choice(raw["dof"], _DOFS, src, "body.dof")
    return {
        "dof": dof,
        "mass": _number(raw["mass"], src, "body.mass", "kg", gt=0.0),
        "inertia": _inertia(raw["inertia"], dof, src, "body.inertia"),
        "cm_offset": _vector3(raw["cm_offset"], src, "body.cm_offset", "m"),
        "torque_noise": _number(raw["torque_noise"], src, "body.torque_noise", "N m", ge=0.0),
    }


def _norm_masses(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    axes_value = raw["axes"]
    what = "3 rail unit vectors (a 3x3 list, one row per rail, body axes)"
    axes = _matrix3(axes_value, src, "masses.axes", what)
    for i, axis in enumerate(axes):
        norm = math.sqrt(sum(a * a for a in axis))
        if abs(norm - 1.0) > _UNIT_NORM_TOL:
            raise InputError(
                f"{src}: key 'masses.axes': expected unit vectors (norm within "
                f"{_UNIT_NORM_TOL:g} of 1), got rail {i + 1} = {list(axis)!r} with norm "
                f"{norm:.9g}; normalise it in the file"
            )
    masses = raw["mass"]
    if isinstance(masses, list | tuple) and len(masses) != len(axes):
        raise _fail(
            src, "masses.mass", f"one mass per rail ({len(axes)} positive numbers, kg)", masses
        )
    mass = _vector3(masses, src, "masses.mass", "kg")
    if not all(m > 0.0 for m in mass):
        raise _fail(src, "masses.mass", "3 positive numbers (kg)", masses)
    return {
        "mass": mass,
        "axes": axes,
        "travel": _number(raw["travel"], src, "masses.travel", "m", gt=0.0),
        "step": _number(raw["step"], src, "masses.step", "m", ge=0.0),
        "speed": _number(raw["speed"], src, "masses.speed", "m/s", gt=0.0),
        "backlash": _number(raw["backlash"], src, "masses.backlash", "m", ge=0.0),
        "gyro_vibration": _number(
            raw["gyro_vibration"], src, "masses.gyro_vibration", "rad/s", ge=0.0
        ),
        "accel_vibration": _number(
            raw["accel_vibration"], src, "masses.accel_vibration", "-", ge=0.0
        ),
        "drive_torque_noise": _number(
            raw["drive_torque_noise"], src, "masses.drive_torque_noise", "N m", ge=0.0
        ),
    }


def _norm_magnetorquers(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    return {
        "max_dipole": _number(raw["max_dipole"], src, "magnetorquers.max_dipole", "A m^2", gt=0.0)
    }


def _per_wheel(value: object, n: int, src: str, key: str, unit: str, **bounds: float) -> tuple:
    """A number broadcast to ``n`` wheels, or a list of one number per wheel."""
    if isinstance(value, list | tuple | np.ndarray):
        if len(value) != n:
            raise _fail(
                src,
                key,
                f"a number or one per wheel ({n} numbers, {unit}; wheels.axes has {n})",
                value if not isinstance(value, np.ndarray) else value.tolist(),
            )
        return tuple(_number(v, src, key, unit, **bounds) for v in value)
    return (_number(value, src, key, unit, **bounds),) * n


def _norm_wheels(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    value = raw["axes"]
    if isinstance(value, np.ndarray):
        value = value.tolist()
    what = (
        f"1 to {_MAX_WHEELS} spin-axis unit vectors (a list of [x, y, z] rows, one per "
        "wheel, body axes)"
    )
    if not isinstance(value, list | tuple) or not 1 <= len(value) <= _MAX_WHEELS:
        raise _fail(src, "wheels.axes", what, value)
    axes = []
    for i, row in enumerate(value):
        if isinstance(row, np.ndarray):
            row = row.tolist()
        if not isinstance(row, list | tuple) or len(row) != 3:
            raise _fail(src, "wheels.axes", what, value)
        if not all(_is_number(v) and math.isfinite(float(v)) for v in row):
            raise _fail(src, "wheels.axes", what, value)
        axis = tuple(float(v) for v in row)
        norm = math.sqrt(sum(a * a for a in axis))
        if abs(norm - 1.0) > _UNIT_NORM_TOL:
            raise InputError(
                f"{src}: key 'wheels.axes': expected unit vectors (norm within "
                f"{_UNIT_NORM_TOL:g} of 1), got wheel {i + 1} = {list(row)!r} with norm "
                f"{norm:.9g}; normalise it in the file"
            )
        axes.append(axis)
    n = len(axes)
    command = raw["command"]
    if not isinstance(command, str) or command not in WHEEL_COMMANDS:
        raise _fail(
            src, "wheels.command", "one of " + ", ".join(repr(c) for c in WHEEL_COMMANDS), command
        )
    tau = raw["speed_loop_tau"]
    if command == "speed":
        if tau is None:
            raise InputError(
                f"{src}: key 'wheels.speed_loop_tau' is required with wheels.command = "
                "'speed' (s, time constant of the wheel driver's speed loop)"
            )
        tau = _number(tau, src, "wheels.speed_loop_tau", "s", gt=0.0)
    elif tau is not None:
        raise InputError(
            f"{src}: key 'wheels.speed_loop_tau' is only for wheels.command = 'speed', but "
            "command = 'torque'; remove it or set command = 'speed'"
        )
    speeds = raw["speeds"]
    return {
        "axes": tuple(axes),
        "inertia": _per_wheel(raw["inertia"], n, src, "wheels.inertia", "kg m^2", gt=0.0),
        "max_torque": _number(raw["max_torque"], src, "wheels.max_torque", "N m", gt=0.0),
        "max_speed": _number(raw["max_speed"], src, "wheels.max_speed", "rad/s", gt=0.0),
        "command": command,
        "speed_loop_tau": tau,
        "speed_noise": _number(raw["speed_noise"], src, "wheels.speed_noise", "rad/s", ge=0.0),
        "speeds": (0.0,) * n
        if speeds is None or (isinstance(speeds, tuple) and len(speeds) == 0)
        else _per_wheel(speeds, n, src, "wheels.speeds", "rad/s"),
    }


def _norm_field(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    return {"lab": _vector3(raw["lab"], src, "field.lab", "T, lab frame")}


def _norm_cmg(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    return {
        "skew": _number(raw["skew"], src, "cmg.skew", "rad", gt=0.0, lt=math.pi / 2),
        "flywheel_inertia": _number(
            raw["flywheel_inertia"], src, "cmg.flywheel_inertia", "kg m^2", gt=0.0
        ),
        "flywheel_speed": _number(
            raw["flywheel_speed"], src, "cmg.flywheel_speed", "rad/s", gt=0.0
        ),
        "max_gimbal_rate": _number(
            raw["max_gimbal_rate"], src, "cmg.max_gimbal_rate", "rad/s", gt=0.0, allow_inf=True
        ),
        "gimbal_angles": _vector(raw["gimbal_angles"], _N_GIMBALS, src, "cmg.gimbal_angles", "rad"),
    }


def _norm_sensors(raw: Mapping[str, Any], src: str) -> dict[str, Any]:
    return {
        "rate": _number(raw["rate"], src, "sensors.rate", "Hz", gt=0.0),
        "gyro_noise": _number(raw["gyro_noise"], src, "sensors.gyro_noise", "rad/s", ge=0.0),
        "accel_noise": _number(raw["accel_noise"], src, "sensors.accel_noise", "-", ge=0.0),
        "lowpass": _number(raw["lowpass"], src, "sensors.lowpass", "-", gt=0.0, le=1.0),
        "gyro": _boolean(raw["gyro"], src, "sensors.gyro"),
        "attitude_noise": _number(
            raw["attitude_noise"], src, "sensors.attitude_noise", "rad", ge=0.0
        ),
    }


def _boolean(value: Any, src: str, key: str) -> bool:
    if not isinstance(value, bool):
        raise _fail(src, key, "true or false", value)
    return value


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


_TABLE_TYPES: dict[str, type] = {
    "body": Body,
    "masses": Masses,
    "magnetorquers": Magnetorquers,
    "field": Field,
    "cmg": CMG,
    "wheels": Wheels,
    "sensors": Sensors,
}
_PLATFORM_ONLY = ("masses", "magnetorquers", "wheels")
_CMG_ONLY = ("cmg",)


@dataclass(frozen=True)
class Testbed:
    """Nominal model of one air-bearing simulator, with its known effects.

    Parameters
    ----------
    kind : {"platform", "cmg"}
        ``"platform"``: sliding masses and magnetorquers; ``"cmg"``: a pyramid
        of four CMGs.
    name : str
        Free text.
    gravity : float
        m/s^2, > 0; lab-frame gravity is ``[0, 0, -gravity]``.
    body : Body
    masses : Masses or None
        Only for kind ``"platform"``.
    magnetorquers : Magnetorquers or None
        Only for kind ``"platform"``.
    field : Field or None
        Helmholtz-cage field, if any.
    cmg : CMG or None
        Required for kind ``"cmg"``, not allowed otherwise.
    wheels : Wheels or None
        Reaction wheels; only for kind ``"platform"``.
    sensors : Sensors
    effects : dict of str to float, 3-tuple or (yaw_imbalance) 2-tuple of float
        Effects already known to act, by name (:data:`airbearing.io.vocabulary.EFFECTS`).
        Copied and normalised on construction; treat it as read-only.
    source : str
        Where the testbed came from (a path, a built-in name or ``"<memory>"``);
        names the origin in error messages and is not compared.

    Notes
    -----
    Instances are immutable and hashable; :meth:`replace` and
    :meth:`with_effects` return validated copies.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> tb
    Testbed(name='cmg-yaw', kind='cmg', dof=1, mass=0.7628, source='cmg-yaw (built-in)')
    >>> tb.body.yaw_inertia, tb.sensors.rate  # kg m^2, Hz
    (0.00283, 20.0)
    >>> tb.with_effects({"viscous_friction": 1e-4}).effects  # N m s/rad
    {'viscous_friction': 0.0001}
    """

    kind: str
    name: str
    gravity: float
    body: Body
    masses: Masses | None = None
    magnetorquers: Magnetorquers | None = None
    field: Field | None = None
    cmg: CMG | None = None
    wheels: Wheels | None = None
    sensors: Sensors = dataclasses.field(default_factory=Sensors)
    effects: dict[str, EffectValue] = dataclasses.field(default_factory=dict)
    source: str = dataclasses.field(default=_MEMORY, compare=False)

    def __repr__(self) -> str:
        effects = f", effects={sorted(self.effects)}" if self.effects else ""
        return (
            f"Testbed(name={self.name!r}, kind={self.kind!r}, dof={self.body.dof}, "
            f"mass={self.body.mass:.4g}{effects}, source={self.source!r})"
        )

    def __post_init__(self) -> None:
        src = self.source if isinstance(self.source, str) else repr(self.source)
        object.__setattr__(self, "source", src)
        if not isinstance(self.kind, str) or self.kind not in KINDS:
            raise _fail(src, "kind", "one of " + ", ".join(repr(k) for k in KINDS), self.kind)
        if not isinstance(self.name, str):
            raise _fail(src, "name", "a string", self.name)
        object.__setattr__(self, "gravity", _number(self.gravity, src, "gravity", "m/s^2", gt=0.0))
        for table, cls in _TABLE_TYPES.items():
            value = getattr(self, table)
            required = table in ("body", "sensors")
            if value is None and not required:
                continue
            if not isinstance(value, cls):
                expected = f"a {cls.__name__}" + ("" if required else " or None")
                raise _fail(src, table, expected, value)
        other = "cmg" if self.kind == "platform" else "platform"
        wrong = _CMG_ONLY if self.kind == "platform" else _PLATFORM_ONLY
        for table in wrong:
            if getattr(self, table) is not None:
                raise InputError(
                    f"{src}: table [{table}] is only allowed for kind = {other!r}, "
                    f"but kind = {self.kind!r}"
                )
        if self.kind == "cmg" and self.cmg is None:
            raise InputError(
                f"{src}: table [cmg] is required for kind = 'cmg' (with keys "
                "'flywheel_inertia' and 'flywheel_speed')"
            )
        if self.wheels is not None and self.body.dof == 1:
            for i, axis in enumerate(self.wheels.axes):
                if not (abs(axis[0]) <= _UNIT_NORM_TOL and abs(axis[1]) <= _UNIT_NORM_TOL):
                    raise InputError(
                        f"{src}: key 'wheels.axes': expected [0, 0, 1] or [0, 0, -1] for every "
                        f"wheel of a dof = 1 bearing (it turns about body z only), got wheel "
                        f"{i + 1} = {list(axis)!r}"
                    )
        if not isinstance(self.effects, Mapping):
            raise _fail(src, "effects", "a table of effect names to values", self.effects)
        effects: dict[str, EffectValue] = {}
        n_wheels = None if self.wheels is None else self.wheels.n
        for effect_name, value in self.effects.items():
            where = f"{src}: key 'effects.{effect_name}'"
            if effect_name not in EFFECTS:
                raise InputError(
                    f"{where}: unknown effect; valid effects are: {', '.join(EFFECTS)}"
                )
            effects[effect_name] = validate_effect_value(
                effect_name, value, where, n_wheels=n_wheels
            )
        object.__setattr__(self, "effects", effects)

    def __hash__(self) -> int:
        values = tuple(
            tuple(sorted(self.effects.items())) if f.name == "effects" else getattr(self, f.name)
            for f in dataclasses.fields(self)
            if f.compare
        )
        return hash(values)

    @property
    def dof(self) -> int:
        """Rotational degrees of freedom of the bearing (1 or 3), ``body.dof``."""
        return self.body.dof

    def replace(self, **changes: Any) -> Testbed:
        """Return a copy with some fields changed, validated again.

        Parameters
        ----------
        **changes
            Field names and new values, as for :func:`dataclasses.replace`.

        Returns
        -------
        Testbed

        Raises
        ------
        InputError
            If a name is not a field or the result is not a valid testbed.
        """
        valid = [f.name for f in dataclasses.fields(self)]
        unknown = sorted(set(changes) - set(valid))
        if unknown:
            raise InputError(
                f"Testbed.replace: unknown field(s) {', '.join(unknown)}; "
                f"valid fields are: {', '.join(valid)}"
            )
        return dataclasses.replace(self, **changes)

    def with_effects(self, effects: Mapping[str, object]) -> Testbed:
        """Return a copy with effects added, or their values replaced.

        Parameters
        ----------
        effects : mapping of str to float or sequence of 3 (a pair: 2) float
            Effect names and values (units of the vocabulary). Effects not
            named here keep their current value; to remove effects use
            ``replace(effects=...)``.

        Returns
        -------
        Testbed
        """
        return self.replace(effects={**self.effects, **dict(effects)})


# ----------------------------------------------------------------------------
# dict <-> Testbed (the TOML layout of FORMATS.md)

_TOP_KEYS = ("kind", "name", "gravity", *_TABLE_TYPES, "effects")
_TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "body": ("dof", "mass", "inertia", "cm_offset", "torque_noise"),
    "masses": (
        "mass",
        "axes",
        "travel",
        "step",
        "speed",
        "backlash",
        "gyro_vibration",
        "accel_vibration",
        "drive_torque_noise",
    ),
    "magnetorquers": ("max_dipole",),
    "field": ("lab",),
    "cmg": (
        "skew",
        "skew_deg",
        "flywheel_inertia",
        "flywheel_speed",
        "max_gimbal_rate",
        "max_gimbal_rate_deg",
        "gimbal_angles",
    ),
    "wheels": (
        "axes",
        "inertia",
        "max_torque",
        "max_speed",
        "command",
        "speed_loop_tau",
        "speed_noise",
        "speeds",
    ),
    "sensors": ("rate", "gyro_noise", "accel_noise", "lowpass", "gyro", "attitude_noise"),
}
#: Optional [masses] keys written by :func:`testbed_to_dict` only when non-zero.
_VIBRATION_KEYS = ("gyro_vibration", "accel_vibration", "drive_torque_noise")
_REQUIRED: dict[str, tuple[str, ...]] = {
    "body": ("mass", "inertia"),
    "masses": ("mass",),
    "field": ("lab",),
    "cmg": ("flywheel_inertia", "flywheel_speed"),
    "wheels": ("axes", "inertia", "max_torque", "max_speed"),
}
_DEFAULT_DOF = 3
_NORMALISERS = {
    "body": _norm_body,
    "masses": _norm_masses,
    "magnetorquers": _norm_magnetorquers,
    "field": _norm_field,
    "cmg": _norm_cmg,
    "wheels": _norm_wheels,
    "sensors": _norm_sensors,
}


def _check_keys(table: Mapping[str, Any], valid: tuple[str, ...], src: str, prefix: str) -> None:
    for key in table:
        if key not in valid:
            dotted = f"{prefix}.{key}" if prefix else str(key)
            hint = difflib.get_close_matches(str(key), valid, n=1)
            where = f"[{prefix}]" if prefix else "the top level"
            message = f"{src}: unknown key '{dotted}'"
            if hint:
                message += f" (did you mean '{hint[0]}'?)"
            message += f"; valid keys at {where} are: {', '.join(valid)}"
            raise InputError(message)


def _defaults(cls: type) -> dict[str, Any]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def _angle_key(
    table: dict[str, Any],
    name: str,
    src: str,
    unit: str,
    default: float | None,
    *,
    lt_deg: float | None = None,
    allow_inf: bool = False,
) -> float | None:
    """Read ``name`` (rad) or ``name_deg`` (deg), not both; return radians or the default."""
    deg_name = f"{name}_deg"
    if name in table and deg_name in table:
        raise InputError(
            f"{src}: keys 'cmg.{name}' and 'cmg.{deg_name}' both given; "
            f"give only one (radians or degrees)"
        )
    if deg_name in table:
        value = _number(
            table[deg_name],
            src,
            f"cmg.{deg_name}",
            f"deg{unit}",
            gt=0.0,
            lt=lt_deg,
            allow_inf=allow_inf,
        )
        return math.radians(value)
    if name in table:
        lt_rad = None if lt_deg is None else math.radians(lt_deg)
        return _number(
            table[name], src, f"cmg.{name}", f"rad{unit}", gt=0.0, lt=lt_rad, allow_inf=allow_inf
        )
    return default


def _build_table(table_name: str, raw: object, src: str) -> object:
    cls = _TABLE_TYPES[table_name]
    if not isinstance(raw, Mapping):
        raise _fail(src, table_name, "a table", raw)
    table = dict(raw)
    _check_keys(table, _TABLE_KEYS[table_name], src, table_name)
    for key in _REQUIRED.get(table_name, ()):
        if key not in table:
            raise InputError(f"{src}: key '{table_name}.{key}' is required in table [{table_name}]")
    if table_name == "cmg":
        skew = _angle_key(table, "skew", src, "", math.radians(DEFAULT_SKEW_DEG), lt_deg=90.0)
        rate = _angle_key(table, "max_gimbal_rate", src, "/s", math.inf, allow_inf=True)
        for key in ("skew_deg", "max_gimbal_rate_deg"):
            table.pop(key, None)
        table["skew"] = skew
        table["max_gimbal_rate"] = rate
    values = {**_defaults(cls), **table}
    if table_name == "body" and "dof" not in table:
        values["dof"] = _DEFAULT_DOF
    normalised = _NORMALISERS[table_name](values, src)
    return cls(**normalised)


def testbed_from_dict(data: Mapping[str, Any], source: str = _MEMORY) -> Testbed:
    """Build a validated :class:`Testbed` from the layout of a testbed file.

    Parameters
    ----------
    data : mapping
        The parsed TOML document (FORMATS.md layout: ``kind``, ``name``,
        ``gravity`` and the tables ``body``, ``masses``, ``magnetorquers``,
        ``field``, ``cmg``, ``wheels``, ``sensors``, ``effects``). SI units; the keys
        ``cmg.skew_deg`` and ``cmg.max_gimbal_rate_deg`` are in degrees and
        deg/s. Missing keys take the documented defaults (``body.dof`` = 3).
    source : str
        Name of the origin, used in error messages and stored in
        :attr:`Testbed.source`.

    Returns
    -------
    Testbed

    Raises
    ------
    InputError
        On an unknown key, a missing required key (``kind``, ``body.mass``,
        ``body.inertia``; ``[cmg]`` with ``flywheel_inertia`` and
        ``flywheel_speed`` for kind ``"cmg"``), a table not allowed for the
        kind, or a value of the wrong type, shape or range. The message names
        ``source`` and the dotted key.

    Examples
    --------
    >>> import airbearing as ab
    >>> body = {"dof": 1, "mass": 12.0, "inertia": 0.4}  # kg, kg m^2 (yaw only)
    >>> tb = ab.testbed_from_dict({"kind": "platform", "name": "bench", "body": body})
    >>> tb.dof, tb.body.yaw_inertia
    (1, 0.4)
    >>> ab.testbed_from_dict({"kind": "platform", "body": {**body, "mass": -1.0}})
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: <memory>: key 'body.mass': expected a finite number > 0 (kg),
    got -1.0
    """
    src = str(source)
    if not isinstance(data, Mapping):
        raise InputError(f"{src}: expected a table of keys at the top level, got {data!r}")
    _check_keys(data, _TOP_KEYS, src, "")
    for table, value in data.items():  # misspelt keys first: they explain missing ones
        if table in _TABLE_KEYS and isinstance(value, Mapping):
            _check_keys(value, _TABLE_KEYS[table], src, table)
    if "kind" not in data:
        raise InputError(
            f"{src}: key 'kind' is required: one of " + ", ".join(repr(k) for k in KINDS)
        )
    kind = data["kind"]
    if not isinstance(kind, str) or kind not in KINDS:
        raise _fail(src, "kind", "one of " + ", ".join(repr(k) for k in KINDS), kind)
    if "body" not in data:
        raise InputError(f"{src}: table [body] is required (with keys 'mass' and 'inertia')")
    other = "cmg" if kind == "platform" else "platform"
    for table in _CMG_ONLY if kind == "platform" else _PLATFORM_ONLY:
        if table in data:
            raise InputError(
                f"{src}: table [{table}] is only allowed for kind = {other!r}, but kind = {kind!r}"
            )
    if kind == "cmg" and "cmg" not in data:
        raise InputError(
            f"{src}: table [cmg] is required for kind = 'cmg' (with keys "
            "'flywheel_inertia' and 'flywheel_speed')"
        )
    name = data.get("name", "")
    if not isinstance(name, str):
        raise _fail(src, "name", "a string", name)
    gravity = _number(data.get("gravity", DEFAULT_GRAVITY), src, "gravity", "m/s^2", gt=0.0)
    tables: dict[str, Any] = {}
    for table in _TABLE_TYPES:
        if table in data:
            tables[table] = _build_table(table, data[table], src)
    effects_raw = data.get("effects", {})
    if not isinstance(effects_raw, Mapping):
        raise _fail(src, "effects", "a table of effect names to values", effects_raw)
    return Testbed(
        kind=kind,
        name=name,
        gravity=gravity,
        effects=dict(effects_raw),
        source=src,
        **tables,
    )


def _exact_degrees(radians: float) -> float | None:
    """A degree value ``d`` with ``math.radians(d) == radians``, shortest repr; None if none."""
    first = math.degrees(radians)
    candidates = [first]
    up = down = first
    for _ in range(_DEG_SEARCH_ULPS):
        up = math.nextafter(up, math.inf)
        down = math.nextafter(down, -math.inf)
        candidates += [down, up]
    exact = [d for d in candidates if math.radians(d) == radians]
    if not exact:
        return None
    return min(exact, key=lambda d: (len(repr(d)), abs(d - first)))


def _angle_out(out: dict[str, Any], name: str, radians: float) -> None:
    degrees = _exact_degrees(radians)
    if degrees is None:  # no decimal degree value reads back to the same float
        out[name] = radians
    else:
        out[f"{name}_deg"] = degrees


def testbed_to_dict(testbed: Testbed) -> dict[str, Any]:
    """The layout of a testbed file, ready for a TOML writer.

    Parameters
    ----------
    testbed : Testbed

    Returns
    -------
    dict
        Plain dicts, lists, floats, ints and strings in the FORMATS.md
        layout. Every key is written, defaults included; optional tables
        only when present, ``[effects]`` only when non-empty. Angles of
        ``[cmg]`` are written as ``skew_deg`` (deg) and
        ``max_gimbal_rate_deg`` (deg/s) when a degree value reads back to the
        identical float (almost always), else in radians; an infinite
        ``max_gimbal_rate`` is omitted (it is the default). Reading the
        result with :func:`testbed_from_dict` gives an equal Testbed.

    Raises
    ------
    InputError
        If ``testbed`` is not a :class:`Testbed`.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> data = ab.testbed_to_dict(tb)
    >>> sorted(data), data["body"]["inertia"]  # kg m^2
    (['body', 'cmg', 'gravity', 'kind', 'name', 'sensors'], 0.00283)
    >>> ab.testbed_from_dict(data) == tb
    True
    """
    if not isinstance(testbed, Testbed):
        raise InputError(f"testbed_to_dict: expected a Testbed, got {type(testbed).__name__}")
    body = testbed.body
    out: dict[str, Any] = {
        "kind": testbed.kind,
        "name": testbed.name,
        "gravity": testbed.gravity,
        "body": {
            "dof": body.dof,
            "mass": body.mass,
            "inertia": (
                body.inertia
                if isinstance(body.inertia, float)
                else [list(row) for row in body.inertia]
            ),
            "cm_offset": list(body.cm_offset),
            "torque_noise": body.torque_noise,
        },
    }
    if testbed.masses is not None:
        m = testbed.masses
        out["masses"] = {
            "mass": list(m.mass),
            "axes": [list(a) for a in m.axes],
            "travel": m.travel,
            "step": m.step,
            "speed": m.speed,
            "backlash": m.backlash,
        }
        for key in _VIBRATION_KEYS:  # optional: written only when set
            if getattr(m, key):
                out["masses"][key] = getattr(m, key)
    if testbed.magnetorquers is not None:
        out["magnetorquers"] = {"max_dipole": testbed.magnetorquers.max_dipole}
    if testbed.field is not None:
        out["field"] = {"lab": list(testbed.field.lab)}
    if testbed.cmg is not None:
        c = testbed.cmg
        cmg: dict[str, Any] = {}
        _angle_out(cmg, "skew", c.skew)
        cmg["flywheel_inertia"] = c.flywheel_inertia
        cmg["flywheel_speed"] = c.flywheel_speed
        if math.isfinite(c.max_gimbal_rate):
            _angle_out(cmg, "max_gimbal_rate", c.max_gimbal_rate)
        cmg["gimbal_angles"] = list(c.gimbal_angles)
        out["cmg"] = cmg
    if testbed.wheels is not None:
        wh = testbed.wheels
        out["wheels"] = {
            "axes": [list(a) for a in wh.axes],
            "inertia": list(wh.inertia),
            "max_torque": wh.max_torque,
            "max_speed": wh.max_speed,
            "command": wh.command,
        }
        if wh.speed_loop_tau is not None:
            out["wheels"]["speed_loop_tau"] = wh.speed_loop_tau
        out["wheels"]["speed_noise"] = wh.speed_noise
        out["wheels"]["speeds"] = list(wh.speeds)
    s = testbed.sensors
    out["sensors"] = {
        "rate": s.rate,
        "gyro_noise": s.gyro_noise,
        "accel_noise": s.accel_noise,
        "lowpass": s.lowpass,
        "gyro": s.gyro,
        "attitude_noise": s.attitude_noise,
    }
    if testbed.effects:
        out["effects"] = {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in testbed.effects.items()
        }
    return out


# ----------------------------------------------------------------------------
# files


def _parse_toml(content: bytes, src: str) -> dict[str, Any]:
    try:
        return tomllib.loads(content.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise InputError(f"{src}: not a UTF-8 text file ({e})") from e
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{src}: not valid TOML: {e}") from e


def read_testbed(path: str | os.PathLike[str]) -> Testbed:
    """Read and validate a testbed file (TOML, FORMATS.md).

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file.

    Returns
    -------
    Testbed
        With ``source`` set to ``str(path)``.

    Raises
    ------
    InputError
        If the file cannot be read, is not valid TOML or is not a valid
        testbed; the message names the file and the key.

    Examples
    --------
    >>> import airbearing as ab
    >>> path = ab.write_testbed(ab.load_testbed("cmg-yaw"), "bench.toml")
    >>> ab.read_testbed(path).source
    'bench.toml'
    >>> ab.read_testbed("missing.toml")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: missing.toml: no such testbed file
    """
    p = Path(path)
    src = str(path)
    try:
        content = p.read_bytes()
    except FileNotFoundError as e:
        raise InputError(f"{src}: no such testbed file") from e
    except IsADirectoryError as e:
        raise InputError(f"{src}: is a directory, expected a testbed file (.toml)") from e
    except OSError as e:
        raise InputError(f"{src}: cannot read the testbed file: {e.strerror}") from e
    return testbed_from_dict(_parse_toml(content, src), source=src)


def load_testbed(path_or_name: str | os.PathLike[str]) -> Testbed:
    """Load a testbed by built-in name or from a file.

    Parameters
    ----------
    path_or_name : str or path-like
        A built-in name (:data:`BUILTIN_TESTBEDS`: ``"platform-3dof"``,
        ``"cmg-yaw"``) or the path of a ``.toml`` testbed file. A string
        equal to a built-in name always means the built-in; pass
        ``"./cmg-yaw"`` or a :class:`pathlib.Path` for a file of that name.

    Returns
    -------
    Testbed

    Raises
    ------
    InputError
        If the argument is neither a built-in name nor an existing file (the
        message lists the built-ins), or the file is invalid.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed004-platform")
    >>> tb.kind, tb.dof, tb.source
    ('platform', 3, 'seed004-platform (built-in)')
    """
    if isinstance(path_or_name, str) and path_or_name in BUILTIN_TESTBEDS:
        src = f"{path_or_name} (built-in)"
        return testbed_from_dict(_parse_toml(builtin_toml(path_or_name), src), source=src)
    if not isinstance(path_or_name, str | os.PathLike):
        raise InputError(
            f"load_testbed: expected a path or a built-in name, got {path_or_name!r}; "
            f"built-in testbeds are: {', '.join(BUILTIN_TESTBEDS)}"
        )
    if not Path(path_or_name).is_file():
        raise InputError(
            f"{path_or_name}: neither an existing testbed file nor a built-in testbed; "
            f"built-in testbeds are: {', '.join(BUILTIN_TESTBEDS)}"
        )
    return read_testbed(path_or_name)


_HEADER = "# Testbed file (FORMATS.md), written by airbearing. SI units; _deg keys in degrees.\n"


def write_testbed(testbed: Testbed, path: str | os.PathLike[str]) -> Path:
    """Write a testbed file (TOML, FORMATS.md) atomically.

    The text goes to a temporary file in the target directory, which then
    replaces ``path``; a failure leaves no partial file behind.

    Parameters
    ----------
    testbed : Testbed
    path : str or path-like
        Destination ``.toml`` file; an existing file is replaced.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    InputError
        If the directory does not exist or cannot be written.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw").with_effects({"viscous_friction": 1e-4})
    >>> path = ab.write_testbed(tb, "cmg-with-friction.toml")
    >>> path.name, ab.load_testbed(path) == tb
    ('cmg-with-friction.toml', True)
    """
    text = _HEADER + _dumps(testbed_to_dict(testbed))
    return _atomic_write_bytes(Path(path), text.encode("utf-8"))


def _toml_value(value: object) -> str:
    """One TOML value on one line (tomli_w puts every array element on its own line)."""
    if isinstance(value, str):
        return tomli_w.dumps({"x": value})[len("x = ") :].strip()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)  # shortest text that reads back to the same float
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to a testbed file")


def _dumps(document: Mapping[str, Any]) -> str:
    """TOML text of a testbed document: top-level values, then one table per section."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in document.items() if not isinstance(v, Mapping)]
    for name, table in document.items():
        if isinstance(table, Mapping):
            lines += ["", f"[{name}]"]
            lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _atomic_write_bytes(path: Path, content: bytes) -> Path:
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: directory {str(directory)!r} does not exist")
    try:
        # the mode of the file it replaces, or the usual mode of a new data file
        tmp = write_temp(path, content, keep_mode=True)
    except OSError as e:
        raise InputError(f"{path}: cannot write to {str(directory)!r}: {e.strerror}") from e
    try:
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
