"""Argument helpers shared by the command modules."""

from __future__ import annotations

from pathlib import Path

from airbearing.errors import InputError
from airbearing.io.testbed import Testbed, load_testbed
from airbearing.io.vocabulary import EFFECTS

__all__ = ["testbed_arg", "parse_effects", "check_output_path"]


def testbed_arg(value: str) -> Testbed:
    """A testbed given as a path or a built-in name."""
    return load_testbed(value)


def parse_effects(items: list[str] | None, *, option: str = "--effect") -> dict:
    """``NAME=VALUE`` or ``NAME=V1,V2,V3`` strings to an effects mapping (FORMATS.md units)."""
    out: dict = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not value.strip():
            raise InputError(f"{option} '{item}': expected NAME=VALUE, e.g. viscous_friction=2e-6")
        if name not in EFFECTS:
            raise InputError(
                f"{option} '{item}': unknown effect '{name}', expected one of {', '.join(EFFECTS)}"
            )
        try:
            nums = [float(v) for v in value.split(",")]
        except ValueError:
            raise InputError(f"{option} '{item}': '{value}' is not a number or 3 numbers") from None
        if len(nums) not in (1, 3):
            raise InputError(f"{option} '{item}': expected 1 or 3 numbers, got {len(nums)}")
        out[name] = nums[0] if len(nums) == 1 else tuple(nums)
    return out


def check_output_path(path: Path | None, option: str, suffixes: tuple[str, ...]) -> None:
    """Refuse an output path with the wrong suffix or in a missing folder before any work."""
    if path is None:
        return
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(f"{option} {path}: expected a file ending in {' or '.join(suffixes)}")
    if not path.parent.exists():
        raise InputError(f"{option} {path}: folder '{path.parent}' does not exist")
