"""airbearing.io: testbed files and logs (the formats of FORMATS.md).

Imports nothing from ``airbearing.models``, ``design`` or ``analysis``.
"""

import importlib

#: Where each public name lives; imported on first use (PEP 562), so that importing one
#: submodule (e.g. ``airbearing.io.builtins`` or ``airbearing.io.output`` at CLI start-up)
#: does not import pandas through ``airbearing.io.log``.
_WHERE = {
    **dict.fromkeys(
        ["COLUMN_GROUPS", "LOG_COLUMNS", "QUATERNION_NORM_TOL", "REQUIRED_COLUMNS", "Log",
         "read_log", "validate_log", "write_log"],
        "log",
    ),
    **dict.fromkeys(
        ["BUILTIN_TESTBEDS", "CMG", "DEFAULT_GRAVITY", "DEFAULT_SKEW_DEG", "KINDS", "Body",
         "Field", "Magnetorquers", "Masses", "Sensors", "Testbed", "WHEEL_COMMANDS", "Wheels",
         "load_testbed", "read_testbed", "testbed_from_dict", "testbed_to_dict", "write_testbed"],
        "testbed",
    ),
    **dict.fromkeys(
        ["EFFECTS", "EffectSpec", "EffectValue", "validate_effect_value"], "vocabulary"
    ),
}  # fmt: skip


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"airbearing.io.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'airbearing.io' has no attribute {name!r}")


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
    "WHEEL_COMMANDS",
    "Wheels",
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
