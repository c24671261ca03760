"""Help text that shows what to type: choices and plain value names, never Python types.

typer prints an option's Python annotation as its value name (``<list[str]>``,
``<int range>``, ``<str>`` for a choice given as a plain string). :func:`install`
replaces that with the names a person reads: the choices ``slew|free|spindown``, or
``NUM``, ``INT``, ``TEXT``, ``PATH``, and for a tuple one name per value
(``NUM NUM NUM``). The unit is in each option's help sentence. Positional arguments
show their upper-case name only (``TESTBED``, ``LOG...``). A number's range is said
in its help sentence, not repeated after the default. Called once at start-up.
"""

from __future__ import annotations

import datetime
import enum
import re
from pathlib import Path
from typing import get_args, get_origin

__all__ = ["install", "value_name", "short_help"]

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


#: Abbreviations whose period ends no sentence ("seed 001 eqs. 1-3", "e.g. ...").
_ABBREVIATIONS = ("eq.", "eqs.", "e.g.", "i.e.", "Fig.", "cf.", "vs.", "approx.")


def short_help(text: str, limit: int = 60) -> str:
    """A command's line in its group's list: its help's first sentence, never cut in
    the middle of a phrase. A sentence longer than ``limit`` loses its parenthetical
    details; what is still longer wraps on the next line instead of ending in "..."."""
    words = " ".join(str(text or "").split()).split(" ")
    sentence: list[str] = []
    for w in words:
        sentence.append(w)
        if w.endswith(".") and not w.endswith(_ABBREVIATIONS):
            break
    first = " ".join(sentence).strip()
    if len(first) > limit:
        plain = re.sub(r"\s*\([^()]*\)", "", first)
        first = plain if plain else first
    return first


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

    # the help sentence states an option's range in words ("Seed of the sensor noise,
    # >= 0."): not again as "[default: 0; x>=0]"
    core.TyperOption._get_number_range_help_str = lambda self: None

    def get_short_help_str(self, limit: int = 45) -> str:
        if self.short_help:
            return " ".join(str(self.short_help).split())
        return short_help(self.help or "")

    core.TyperCommand.get_short_help_str = get_short_help_str
    core.TyperGroup.get_short_help_str = get_short_help_str
    core.TyperArgument._usage_display_name = usage_name
    core.TyperArgument.display_name_raw = property(
        lambda self: self.metavar if self.metavar is not None else str(self.name).upper()
    )
    _INSTALLED["done"] = True
