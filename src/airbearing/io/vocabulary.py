"""The effect vocabulary of FORMATS.md ("Effects: names and parameters") as data.

An effect is a named physical or measurement phenomenon that the nominal model
of a testbed lacks. The same names appear in the ``[effects]`` table of a
testbed file, in the output of the discrepancy workflow and in the reports.
This module only knows the names, units and value shapes; what an effect does
to the dynamics is the business of ``airbearing.models``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from airbearing.errors import InputError

__all__ = ["EFFECTS", "MAX_WHEELS", "EffectSpec", "EffectValue", "validate_effect_value"]

Shape = Literal["scalar", "scalar_or_axes", "vector3", "pair", "scalar_or_wheels"]
EffectValue = float | tuple[float, ...]

_SHAPES: tuple[str, ...] = ("scalar", "scalar_or_axes", "vector3", "pair", "scalar_or_wheels")
#: Most reaction wheels of a testbed (FORMATS.md: 1 to 6 rows of ``wheels.axes``).
MAX_WHEELS = 6

#: SI: a value this little below a non-strict bound (0 for friction and drag) is the
#: roundoff of a solver that ended at the bound (an interior-point fit: -7e-19 seen) and
#: is read as the bound. Real rigs' friction and drag are 1e-7 or more (effect-ranges.md),
#: so 1e-10 never hides a genuinely negative value.
ROUNDOFF = 1e-10


@dataclass(frozen=True)
class EffectSpec:
    """Name, unit and value shape of one effect.

    Attributes
    ----------
    name : str
        The effect's name, as used in files and reports.
    unit : str
        SI unit of the value ("-" for dimensionless).
    description : str
        What the effect changes (torque or measurement), one line.
    shape : {"scalar", "scalar_or_axes", "vector3", "pair"}
        ``"scalar"``: one number. ``"scalar_or_axes"``: one number that applies
        to every free body axis, or a list of three (one per body axis).
        ``"vector3"``: a 3-vector in body axes. ``"pair"``: two numbers (the
        sine and cosine amplitudes of ``yaw_imbalance``). ``"scalar_or_wheels"``: one
        number for every reaction wheel, or a list with one entry per wheel.
    lower : float or None
        Smallest admissible value of each component, or None for no bound.
    lower_strict : bool
        True if the bound itself is excluded (``value > lower``).
    """

    name: str
    unit: str
    description: str
    shape: Shape
    lower: float | None = None
    lower_strict: bool = False

    def __post_init__(self) -> None:
        if self.shape not in _SHAPES:
            raise InputError(
                f"effect {self.name!r}: shape must be one of {', '.join(_SHAPES)}, "
                f"got {self.shape!r}"
            )


_SPECS: tuple[EffectSpec, ...] = (
    EffectSpec(
        "inertia_error",
        "-",
        "inertia is (1 + value) * inertia",
        "scalar",
        lower=-1.0,  # (1 + value) must stay > 0 to keep the inertia positive definite
        lower_strict=True,
    ),
    EffectSpec(
        "viscous_friction",
        "N m s",
        "tau_i = -c_i * w_i, per body axis",
        "scalar_or_axes",
        lower=0.0,  # dissipative: a negative value feeds energy in (FORMATS.md)
    ),
    EffectSpec(
        "coulomb_friction",
        "N m",
        "tau_i = -f_i * sign(w_i), per body axis (smoothed near zero rate)",
        "scalar_or_axes",
        lower=0.0,  # dissipative: a negative value feeds energy in (FORMATS.md)
    ),
    EffectSpec(
        "aero_drag",
        "N m s^2",
        "tau_i = -k_i * abs(w_i) * w_i, per body axis",
        "scalar_or_axes",
        lower=0.0,  # dissipative: a negative value feeds energy in (FORMATS.md)
    ),
    EffectSpec(
        "spring_torque",
        "N m / rad",
        "tau_z = -k * yaw (cables, umbilical), dof = 1",
        "scalar",
    ),
    EffectSpec(
        "yaw_imbalance",
        "N m",
        "tau_z = A_s * sin(yaw) + A_c * cos(yaw), value [A_s, A_c] (tilted bearing axis, "
        "CM off it: gravity torque once per turn), dof = 1",
        "pair",
    ),
    EffectSpec(
        "cm_offset_error",
        "m",
        "extra CR -> CM offset dr: tau = mass * dr x g_body",
        "vector3",
    ),
    EffectSpec(
        "residual_dipole",
        "A m^2",
        "tau = m_res x b_body",
        "vector3",
    ),
    EffectSpec(
        "gyro_bias",
        "rad/s",
        "measured w = true w + bias",
        "scalar_or_axes",
    ),
    EffectSpec(
        "sensor_lag",
        "s",
        "measured w passes a first-order lag of time constant tau",
        "scalar",
        lower=0.0,
    ),
    EffectSpec(
        "gimbal_deadzone",
        "rad/s",
        "commanded gimbal rates below the value give no motion",
        "scalar",
        lower=0.0,
    ),
    EffectSpec(
        "wheel_viscous_friction",
        "N m s",
        "wheel bearing: tau_f_i = c_i * W_i, per wheel",
        "scalar_or_wheels",
        lower=0.0,  # dissipative
    ),
    EffectSpec(
        "wheel_coulomb_friction",
        "N m",
        "wheel bearing: tau_f_i = f_i * sign(W_i), per wheel (smoothed near zero speed)",
        "scalar_or_wheels",
        lower=0.0,  # dissipative
    ),
    EffectSpec(
        "wheel_torque_error",
        "-",
        "the motor gives (1 + value_i) times the commanded torque, command = torque",
        "scalar_or_wheels",
        lower=-1.0,  # (1 + value) > 0: a motor that turns the other way is no error
        lower_strict=True,
    ),
    EffectSpec(
        "wheel_inertia_error",
        "-",
        "Iw_i is (1 + value_i) * Iw_i",
        "scalar_or_wheels",
        lower=-1.0,  # (1 + value) > 0 keeps the wheel inertia positive
        lower_strict=True,
    ),
)

#: Every effect name of FORMATS.md, in the order of its table.
EFFECTS: dict[str, EffectSpec] = {spec.name: spec for spec in _SPECS}


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _component(spec: EffectSpec, value: object, where: str) -> float:
    if not _is_number(value):
        shown = str(value).lower() if isinstance(value, bool) else repr(value)  # TOML true
        raise InputError(f"{where}: expected a number ({spec.unit}), got {shown}")
    x = float(value)  # type: ignore[arg-type]
    if not math.isfinite(x):
        raise InputError(f"{where}: expected a finite number ({spec.unit}), got {value!r}")
    if spec.lower is not None:
        unit = "" if spec.unit == "-" else f" {spec.unit}"
        if spec.lower_strict and not x > spec.lower:
            raise InputError(f"{where}: expected a value > {spec.lower:g}{unit}, got {value!r}")
        if not spec.lower_strict and spec.lower - ROUNDOFF <= x < spec.lower:
            x = spec.lower  # a fit pinned at its bound, ended a roundoff beyond it
        if not spec.lower_strict and not x >= spec.lower:
            raise InputError(f"{where}: expected a value >= {spec.lower:g}{unit}, got {value!r}")
    return x


def validate_effect_value(
    name: str, value: object, where: str, *, n_wheels: int | None = None
) -> EffectValue:
    """Check one effect value against the vocabulary and return it normalised.

    Parameters
    ----------
    name : str
        Effect name; must be a key of :data:`EFFECTS`.
    value : object
        The value as read (a number, or a sequence of three numbers; two for a pair).
        Integers are accepted as floats; booleans are not numbers.
    where : str
        Location used as the prefix of error messages, for example
        ``"bench.toml: key 'effects.viscous_friction'"``.
    n_wheels : int, optional
        Number of reaction wheels of the testbed, when known: a per-wheel list of a
        ``wheel_*`` effect must have that many entries.

    Returns
    -------
    float or tuple of 2 or 3 float
        The value in the unit of :attr:`EffectSpec.unit`: a float for a single
        number, a tuple of three floats (body axes x, y, z) for a list, a tuple of
        two floats ``(A_s, A_c)`` for a pair, a tuple of one float per wheel for a
        per-wheel list.

    Raises
    ------
    InputError
        If the name is not in the vocabulary (the message lists the valid
        names), or the value has the wrong shape, is not finite, or is below
        the effect's bound.
    """
    spec = EFFECTS.get(name)
    if spec is None:
        raise InputError(
            f"{where}: unknown effect {name!r}; valid effects are: {', '.join(EFFECTS)}"
        )
    if spec.shape == "scalar":
        return _component(spec, value, where)
    if spec.shape == "scalar_or_axes" and _is_number(value):
        return _component(spec, value, where)
    if spec.shape == "scalar_or_wheels":
        if _is_number(value):
            return _component(spec, value, where)
        count = f"{n_wheels}" if n_wheels is not None else f"1 to {MAX_WHEELS}"
        expected = f"a number or a list of {count} numbers (one per wheel)"
        if not isinstance(value, list | tuple) or not 1 <= len(value) <= MAX_WHEELS:
            raise InputError(f"{where}: expected {expected}, got {value!r}")
        if n_wheels is not None and len(value) != n_wheels:
            raise InputError(
                f"{where}: expected {expected} (wheels.axes has {n_wheels} wheels), "
                f"got {len(value)} values {list(value)!r}"
            )
        return tuple(_component(spec, v, where) for v in value)
    if spec.shape == "pair":
        if not isinstance(value, list | tuple) or len(value) != 2:
            raise InputError(f"{where}: expected a list of 2 numbers [A_s, A_c], got {value!r}")
        a, b = (_component(spec, v, where) for v in value)
        return (a, b)
    expected = (
        "a number or a list of 3 numbers (per body axis)"
        if spec.shape == "scalar_or_axes"
        else "a list of 3 numbers (body axes)"
    )
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise InputError(f"{where}: expected {expected}, got {value!r}")
    x, y, z = (_component(spec, v, where) for v in value)
    return (x, y, z)
