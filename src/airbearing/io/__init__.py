"""airbearing.io: testbed files and logs (the formats of FORMATS.md).

Imports nothing from ``airbearing.models``, ``design`` or ``analysis``.
"""

from airbearing.io.log import (
    COLUMN_GROUPS,
    LOG_COLUMNS,
    QUATERNION_NORM_TOL,
    REQUIRED_COLUMNS,
    Log,
    read_log,
    validate_log,
    write_log,
)
from airbearing.io.testbed import (
    BUILTIN_TESTBEDS,
    CMG,
    DEFAULT_GRAVITY,
    DEFAULT_SKEW_DEG,
    KINDS,
    Body,
    Field,
    Magnetorquers,
    Masses,
    Sensors,
    Testbed,
    load_testbed,
    read_testbed,
    testbed_from_dict,
    testbed_to_dict,
    write_testbed,
)
from airbearing.io.vocabulary import EFFECTS, EffectSpec, EffectValue, validate_effect_value

__all__ = [
    "BUILTIN_TESTBEDS",
    "CMG",
    "COLUMN_GROUPS",
    "DEFAULT_GRAVITY",
    "DEFAULT_SKEW_DEG",
    "EFFECTS",
    "KINDS",
    "LOG_COLUMNS",
    "QUATERNION_NORM_TOL",
    "REQUIRED_COLUMNS",
    "Body",
    "EffectSpec",
    "EffectValue",
    "Field",
    "Log",
    "Magnetorquers",
    "Masses",
    "Sensors",
    "Testbed",
    "load_testbed",
    "read_log",
    "read_testbed",
    "testbed_from_dict",
    "testbed_to_dict",
    "validate_effect_value",
    "validate_log",
    "write_log",
    "write_testbed",
]
