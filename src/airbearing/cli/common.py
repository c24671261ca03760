"""Argument helpers shared by the command modules: testbeds, effects, numbers, outputs.

Everything here is light to import (no numpy at module level): the command modules
import it at start-up. Numbers in messages are printed plainly (:func:`fmt`), never as
``np.float64(5.0)``.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from pathlib import Path

from airbearing.errors import InputError

__all__ = [
    "testbed_arg",
    "testbed_input",
    "parse_effects",
    "check_output_path",
    "fmt",
    "number",
    "numbers",
    "check_log_size",
    "MEMORY_FRACTION",
    "given",
    "refuse_given",
    "as_flags",
    "only_as_flag",
    "as_typed",
    "typed_value",
]

#: Largest share of the machine's memory a command's log may need before it is refused.
MEMORY_FRACTION = 0.25


def fmt(value) -> str:
    """A number as a person writes it (``5``, ``0.001``, ``1e+09``, ``nan``), any numeric type."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f"{v:.8g}"


def testbed_arg(value: str):
    """A testbed given as a path or a built-in name (:func:`airbearing.io.testbed.load_testbed`)."""
    from airbearing.io.testbed import load_testbed

    return load_testbed(value)


def testbed_input(outputs, value: str | None) -> None:
    """Declare a testbed argument as an input of ``outputs`` when it names a file."""
    if value is not None and Path(value).is_file():
        outputs.input(Path(value), "the testbed")


def parse_effects(items: list[str] | None, *, option: str = "--effect") -> dict:
    """``NAME=VALUE``, ``NAME=V1,V2,V3`` or (a pair) ``NAME=V1,V2`` to an effects mapping (SI)."""
    from airbearing.io.vocabulary import EFFECTS

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
        shape = EFFECTS[name].shape
        if shape == "scalar_or_wheels":  # one value, or one per wheel (the testbed checks n)
            counts, want = None, "1 number or one per wheel"
        elif shape == "pair":  # yaw_imbalance=A_S,A_C
            counts, want = (2,), "2 numbers A_S,A_C"
        else:
            counts, want = (1, 3), "1 or 3 numbers"
        if counts is not None and len(nums) not in counts:
            raise InputError(f"{option} '{item}': expected {want}, got {len(nums)}")
        if not all(math.isfinite(v) for v in nums):
            raise InputError(f"{option} '{item}': expected finite numbers")
        from airbearing.io.vocabulary import validate_effect_value

        value = nums[0] if len(nums) == 1 else tuple(nums)
        out[name] = validate_effect_value(name, value, f"{option} {item}")  # bounds, unit
    return out


def number(
    option: str,
    value,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
    unit: str = "",
    why: str = "",
):
    """Check one numeric option: finite and within ``[lo, hi]`` (open ends on request).

    Returns the value unchanged (``None`` passes). Raises :class:`InputError` naming the
    option, the value and the accepted range (with ``unit``), plus ``why`` if given.
    """
    if value is None:
        return None
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None:
        rng = f"from {fmt(lo)} to {fmt(hi)}{u}"
        if lo_open or hi_open:
            rng = (
                f"{'>' if lo_open else '>='} {fmt(lo)} and {'<' if hi_open else '<='} {fmt(hi)}{u}"
            )
    elif lo is not None:
        rng = f"{'>' if lo_open else '>='} {fmt(lo)}{u}"
    elif hi is not None:
        rng = f"{'<' if hi_open else '<='} {fmt(hi)}{u}"
    else:
        rng = ""
    expected = f"expected a finite number{' ' + rng if rng else ''}"
    v = float(value)
    bad = not math.isfinite(v)
    if not bad and lo is not None:
        bad = v <= lo if lo_open else v < lo
    if not bad and hi is not None:
        bad = v >= hi if hi_open else v > hi
    if bad:
        raise InputError(f"{option} {fmt(value)}: {expected}{'; ' + why if why else ''}")
    return value


def numbers(option: str, values, **kw):
    """:func:`number` for each entry of a tuple option (``None`` passes)."""
    if values is None:
        return None
    for v in values:
        try:
            number(option, v, **kw)
        except InputError as e:
            shown = " ".join(fmt(x) for x in values)
            raise InputError(str(e).replace(f"{option} {fmt(v)}", f"{option} {shown}", 1)) from None
    return values


def _memory_bytes() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


def _size(n_bytes: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 2**10:.3g} KiB"


def check_log_size(option: str, duration: float, rate_hz: float, columns: int = 40) -> None:
    """Refuse a run whose log would not fit in memory, saying the size it would need.

    ``columns`` float64 values per sample (the log plus the simulator's states and
    outputs); the limit is :data:`MEMORY_FRACTION` of the machine's memory.
    """
    rows = duration * rate_hz + 1
    need = rows * columns * 8.0 * 3  # the arrays, the log's table and one copy
    limit = MEMORY_FRACTION * _memory_bytes()
    if need > limit:
        longest = limit / (columns * 8.0 * 3) / rate_hz
        raise InputError(
            f"{option} {fmt(duration)} s: the log would have {rows:.3g} rows at {fmt(rate_hz)} Hz "
            f"and need about {_size(need)} of memory (this machine allows {_size(limit)}); "
            f"expected at most {longest:.3g} s"
        )


def check_output_path(path: Path | None, option: str, suffixes: tuple[str, ...]) -> None:
    """Refuse an output path with the wrong suffix or in a missing/unwritable folder.

    Kept for command modules that do not use :class:`airbearing.cli.outputs.Outputs` yet;
    the same checks as :meth:`Outputs.plan`.
    """
    if path is None:
        return
    from airbearing.cli.outputs import Outputs

    Outputs().plan(path, option, suffixes)


def _current_context():
    """The parser's context of the command being run, or ``None`` outside a command."""
    try:
        from typer._click.globals import get_current_context
    except ImportError:  # a typer that uses click itself
        from click import get_current_context
    return get_current_context(silent=True)


def as_typed(option: str) -> str:
    """``option`` (any spelling of one option of the running command, ``-o``) as the
    user typed it: ``--out``, or the old spelling rewritten to it (``--log``,
    ``--output``). ``option`` itself outside a command or when it was not typed."""
    from airbearing.cli import GLOBAL
    from airbearing.cli.grammar import TYPED

    ctx = _current_context()
    if ctx is None:
        return option
    argv = GLOBAL.get("argv") or []
    for param in ctx.command.params:
        opts = list(getattr(param, "opts", []) or []) + list(getattr(param, "secondary_opts", []))
        if option not in opts:
            continue
        for a in reversed(argv):  # the last one given is the one that counts
            for o in opts:
                if a == o or (o.startswith("--") and a.startswith(o + "=")):
                    return TYPED.get(o, o)
    return option


def given(*names: str) -> list[str]:
    """The options among parameters ``names`` that were given on the command line.

    Each is named as the user typed it (``-o`` or ``--out``, or the old spelling
    typed); an option left at its default is not given. One typed with its default value
    is: ``balance --two-step --duration 300`` asks for a run length the two-step does not
    use (the help says which modes an option's default belongs to). Outside a command (a
    direct call in a test), nothing is given.
    """
    ctx = _current_context()
    if ctx is None:
        return []
    try:
        from typer._click.core import ParameterSource
    except ImportError:
        from click.core import ParameterSource
    from airbearing.cli import GLOBAL

    argv = GLOBAL.get("argv") or []
    out = []
    for param in ctx.command.params:
        if param.name not in names or not getattr(param, "opts", None):
            continue
        if ctx.get_parameter_source(param.name) != ParameterSource.COMMANDLINE:
            continue
        opts = list(param.opts) + list(getattr(param, "secondary_opts", []))
        typed = [o for o in opts if any(a == o or a.startswith(o + "=") for a in argv)]
        out.append(as_typed(typed[0]) if typed else max(opts, key=len))
    return out


def refuse_given(names, why: str) -> None:
    """Refuse the first option among ``names`` given on the command line: one line
    ``OPTION: why`` (an option that does not apply to what was asked)."""
    found = given(*names)
    if found:
        raise InputError(f"{found[0]}: {why}")


def _typed_values(flag: str) -> str | None:
    """The value(s) typed after ``flag`` on the command line (up to the next option)."""
    from airbearing.cli import GLOBAL

    argv = list(GLOBAL.get("argv") or [])
    for i in range(len(argv) - 1, -1, -1):
        if argv[i].startswith(flag + "="):
            return argv[i][len(flag) + 1 :]
        if argv[i] == flag:
            vals = []
            for a in argv[i + 1 :]:
                if a.startswith("-") and len(a) > 1 and not (a[1].isdigit() or a[1] == "."):
                    break
                vals.append(a)
            return " ".join(vals)
    return None


def typed_value(flag: str, value) -> str:
    """The value(s) of ``flag`` as typed on the command line (``0``, not the parsed
    ``0.0``), or ``value`` written plainly (:func:`fmt`) outside a command."""
    typed = _typed_values(flag)
    return typed if typed else fmt(value)


@contextlib.contextmanager
def as_flags(**flags: str):
    """The library's messages about its parameters, named by the command's flags.

    ``as_flags(sliders="--sliders")``: an :class:`InputError` ``sliders=[1.0, 0.0, 0.0]:
    each must lie within ...`` leaves as ``--sliders 1 0 0: each must lie within ...``
    (the value as typed). Only for parameters in the same unit as their flag.
    """
    try:
        yield
    except InputError as e:
        msg = str(e)
        for param, flag in flags.items():
            if msg.startswith(param + "=") and ": " in msg:
                typed = _typed_values(flag)
                if typed is not None:
                    raise InputError(f"{flag} {typed}: {msg.split(': ', 1)[1]}") from None
        raise


@contextlib.contextmanager
def only_as_flag():
    """The library's ``only='NAME': ...`` messages as ``--only NAME: ...`` (each name of a
    repeated ``--only`` is its own)."""
    try:
        yield
    except InputError as e:
        m = re.match(r"only='([^']*)': (.*)", str(e), re.S)
        if m is None:
            raise
        raise InputError(f"--only {m.group(1)}: {m.group(2)}") from None
