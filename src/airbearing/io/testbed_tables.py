"""The tables of a testbed file (FORMATS.md): their keys, required keys and normalisers.

One normaliser per table (``[body]``, ``[masses]``, ``[magnetorquers]``, ``[field]``,
``[cmg]``, ``[wheels]``, ``[sensors]``) turns the raw values of its keys (defaults
filled in) into validated values with the same keys; the dataclasses of
:mod:`airbearing.io.testbed` run them on construction, so a table read from a file and one
built in Python are checked alike. The file layout (``_TOP_KEYS``, ``_TABLE_KEYS``,
``_REQUIRED``, the tables each kind allows or needs, ``KINDS`` and the defaults) and its
checks (an unknown key with the nearest valid one, an angle given in radians or in
degrees, the top level: ``_check_top_level``) are here too.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from airbearing.errors import InputError
from airbearing.io.testbed_values import (
    _boolean,
    _fail,
    _inertia,
    _integer_choice,
    _is_number,
    _matrix3,
    _number,
    _vector,
    _vector3,
)

__all__ = ["DEFAULT_GRAVITY", "DEFAULT_SKEW_DEG", "KINDS", "WHEEL_COMMANDS"]

#: Values of the top-level ``kind`` key.
KINDS: tuple[str, ...] = ("platform", "cmg")
#: m/s^2, default of the top-level ``gravity`` key (FORMATS.md).
DEFAULT_GRAVITY = 9.81
#: deg, default CMG pyramid skew angle (seed 001 Table 6: beta = 54.73 deg).
DEFAULT_SKEW_DEG = 54.73

_DOFS = (1, 3)
_UNIT_NORM_TOL = 1e-6  # |norm - 1| allowed for a rail axis
_N_GIMBALS = 4
_MAX_WHEELS = 6
#: Values of ``wheels.command``: the logged command is a motor torque or a wheel speed.
WHEEL_COMMANDS: tuple[str, ...] = ("torque", "speed")


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


# ----------------------------------------------------------------------------
# the file layout

#: The keys of each table, in the order a file is written and a message lists them.
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
_TOP_KEYS = ("kind", "name", "gravity", *_TABLE_KEYS, "effects")
#: Optional [masses] keys, written (``testbed_to_dict``) only when non-zero.
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
#: Tables allowed for kind "platform" only, and for kind "cmg" only.
_PLATFORM_ONLY = ("masses", "magnetorquers", "wheels")
_CMG_ONLY = ("cmg",)


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


def _check_top_level(data: object, src: str) -> tuple[str, str, float]:
    """Check a document's top level and which tables its kind allows or needs.

    Unknown keys first (of the top level, then of each table: a misspelt key explains a
    missing one), then ``kind``, the tables the kind requires or forbids, ``name`` and
    ``gravity``. Returns ``(kind, name, gravity)``; ``gravity`` in m/s^2.
    """
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
    return kind, name, gravity
