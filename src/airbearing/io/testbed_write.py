"""Writing a testbed file: a document (:func:`~airbearing.io.testbed.testbed_to_dict`) to TOML.

Every value on one line, in the key order of the document; floats as their shortest
round-trip text; an angle in degrees when a degree value reads back to the identical
float (``_angle_out``). The front door is :func:`airbearing.io.testbed.write_testbed`;
``_atomic_write_bytes`` (a temporary file, then a rename) also writes logs.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomli_w

from airbearing.errors import InputError
from airbearing.io.output import write_temp
from airbearing.io.testbed_tables import _VIBRATION_KEYS

if TYPE_CHECKING:
    from airbearing.io.testbed import Testbed

_DEG_SEARCH_ULPS = 8  # neighbours tried to find a degree value that reads back exactly
_HEADER = "# Testbed file (FORMATS.md), written by airbearing. SI units; _deg keys in degrees.\n"


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


def _testbed_document(testbed: Testbed) -> dict[str, Any]:
    """The layout of a testbed file (``testbed_to_dict``, which checks the type first)."""
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
