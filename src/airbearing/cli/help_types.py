"""Help text that shows what to type: choices and plain value names, never Python types.

typer prints an option's Python annotation as its value name (``<list[str]>``,
``<int range>``, ``<str>`` for a choice given as a plain string). :func:`install`
replaces that with the names a person reads: the choices ``slew|free|spindown``, or
``NUM``, ``INT``, ``TEXT``, ``PATH``, and for a tuple one name per value
(``NUM NUM NUM``). The unit is in each option's help sentence. Positional arguments
show their upper-case name only (``TESTBED``, ``LOG...``). Called once at start-up.
"""

from __future__ import annotations

import datetime
import enum
from pathlib import Path
from typing import get_args, get_origin

__all__ = ["install", "value_name"]

_INSTALLED = {"done": False}


def _name_of(annotation) -> str:
    if isinstance(annotation, type):
        if issubclass(annotation, bool):
            return "yes|no"
        if issubclass(annotation, int):
            return "INT"
        if issubclass(annotation, float):
            return "NUM"
        if issubclass(annotation, Path):
            return "PATH"
        if issubclass(annotation, enum.Enum):
            return "|".join(str(m.value) for m in annotation)
        if issubclass(annotation, datetime.datetime):
            return "DATE"
    return "TEXT"


def value_name(param) -> str:
    """The value name of a typer parameter in help (choices, ``NUM``, ``PATH``, ...)."""
    desc = param.type_descriptor
    if desc.is_choice and desc.choices is not None:
        return "|".join(str(getattr(c, "value", c)) for c in desc.choices)
    annotation = desc.annotation
    if desc.is_tuple:
        return " ".join(_name_of(a) for a in get_args(annotation))
    if get_origin(annotation) is list:
        (inner,) = get_args(annotation) or (str,)
        return _name_of(inner)
    if desc.is_path:
        return "PATH"
    return _name_of(annotation)


def install() -> None:
    """Make every typer option show :func:`value_name` (once per process)."""
    if _INSTALLED["done"]:
        return
    from typer import core

    def display_type(self, ctx) -> str:
        return value_name(self)

    def option_display(self, ctx) -> str | None:
        return self.metavar if self.metavar is not None else value_name(self)

    def argument_display(self, ctx) -> str | None:
        return None  # the argument's upper-case name says it all

    core._TyperParameter.display_type = display_type
    core.TyperOption.display_type_rich = option_display
    core.TyperArgument.display_type_rich = argument_display

    def usage_name(self) -> str:
        name = self.display_name_raw
        if self.nargs != 1 and self.metavar is None:
            name += "..."
        return name if self.required else f"[{name}]"

    core.TyperArgument._usage_display_name = usage_name
    core.TyperArgument.display_name_raw = property(
        lambda self: self.metavar if self.metavar is not None else str(self.name).upper()
    )
    _INSTALLED["done"] = True
