"""The parser's errors as the one line of the command line's grammar.

A value the parser refuses (not a number, below an option's minimum, not among its
choices) reads as every other bad value does: ``--noise-seed -1: expected a value >= 0``,
naming the option as typed and the value, instead of the parser's own
``airbearing simulate: Invalid value for '--noise-seed': Input should be ...``.
Other usage errors (an unknown option, a missing argument) keep the parser's words,
after the command they belong to.
"""

from __future__ import annotations

import re

__all__ = ["usage_line"]

#: The parser's (pydantic's) phrases and what the rest of the command line says.
_PHRASES = (
    ("a valid integer, unable to parse string as an integer", "an integer"),
    ("a valid number, unable to parse string as a number", "a number"),
    ("a valid integer, got a number with a fractional part", "an integer"),
    ("a valid integer", "an integer"),
    ("a valid number", "a number"),
    ("a finite number", "a finite number"),
    ("greater than or equal to ", ">= "),
    ("less than or equal to ", "<= "),
    ("greater than ", "> "),
    ("less than ", "< "),
)


def _plain(message: str) -> str:
    """The parser's reason in the words of :func:`airbearing.cli.common.number`."""
    text = " ".join(str(message).split()).rstrip(".")
    choice = re.match(r"^'?(.*?)'? is not one of (.*)$", text)
    if choice:
        names = [n.strip(" '") for n in choice.group(2).split(",")]
        return f"expected one of {', '.join(names)}"
    if text.startswith("Input should be "):
        text = "expected " + text[len("Input should be ") :]
        for old, new in _PHRASES:
            text = text.replace(old, new)
        text = re.sub(r"^expected ([<>]=?) ", r"expected a value \1 ", text)
        return text
    return text[:1].lower() + text[1:]


def _typed(param, args: list[str]) -> tuple[str, str] | None:
    """The option as the user typed it and the value(s) after it, from ``args``."""
    opts = list(getattr(param, "opts", []) or []) + list(getattr(param, "secondary_opts", []))
    nargs = max(int(getattr(param, "nargs", 1) or 1), 1)
    for i in range(len(args) - 1, -1, -1):  # the last one given is the one that counts
        a = args[i]
        for o in opts:
            if a == o:
                return o, " ".join(args[i + 1 : i + 1 + nargs])
            if a.startswith(o + "="):
                return o, a[len(o) + 1 :]
    return None


def usage_line(error, args: list[str]) -> str:
    """One line for a usage error of the parser (typer's vendored click exceptions)."""
    ctx = getattr(error, "ctx", None)
    param = getattr(error, "param", None)
    if type(error).__name__ == "BadParameter" and param is not None:
        found = _typed(param, args)
        if getattr(param, "param_type_name", "") == "option" and found is not None:
            option, value = found
            return f"{option} {value}: {_plain(error.message)}"
    if (
        type(error).__name__ == "MissingParameter"
        and getattr(param, "param_type_name", "") == "option"
    ):
        # a required option, as the rest of the grammar says it: "-o/--out: required, ..."
        what = " ".join(str(getattr(param, "help", "") or "").split()).rstrip(".")
        msg = f"{'/'.join(param.opts)}: required" + (
            f" ({what[:1].lower() + what[1:]})" if what else ""
        )
    else:
        msg = " ".join(error.format_message().split()).replace("Value error, ", "")
    if ctx is not None and ctx.command_path:
        # the command's words only: the line already starts "airbearing: error: "
        command = ctx.command_path.split(" ", 1)[1] if " " in ctx.command_path else ""
        if command:
            msg = f"{command}: {msg}"
    return msg
