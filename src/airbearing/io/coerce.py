"""Arguments of the Python API turned into the objects the tools use, or an InputError.

Every public entry point takes a testbed as a :class:`~airbearing.io.testbed.Testbed`, a
built-in name or a testbed file, and logs as :class:`~airbearing.io.log.Log` objects or
log files (one or a list); the helpers here do that once, and say which argument was
wrong and what it accepts, in Python wording (``duration='5'``, not a command-line flag).
A log that belongs to a testbed of another kind or number of degrees of freedom is
refused by every tool (:func:`check_log_testbed`).

Imports nothing outside :mod:`airbearing.io` (and numpy); the heavy modules lazily.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping

import numpy as np

from airbearing.errors import InputError
from airbearing.io.testbed import BUILTIN_TESTBEDS, Testbed, load_testbed
from airbearing.io.vocabulary import validate_effect_value

__all__ = [
    "as_effects",
    "as_float",
    "as_gains",
    "as_int",
    "as_log",
    "as_logs",
    "as_names",
    "as_testbed",
    "as_vector",
    "check_gyro_agrees",
    "check_log_testbed",
]

#: What a testbed argument accepts, in messages.
TESTBED_FORMS = "a Testbed, a built-in testbed name or a testbed file path"
#: What a log argument accepts, in messages.
LOG_FORMS = "a Log or a log file path"


def _is_path(value) -> bool:
    return isinstance(value, str | os.PathLike)


def as_testbed(testbed, name: str = "testbed", *, optional: bool = False):
    """A :class:`~airbearing.io.testbed.Testbed` from itself, a built-in name or a file path.

    Parameters
    ----------
    testbed : Testbed, str or path-like
    name : str
        The argument's name in messages.
    optional : bool
        None is allowed (and returned).

    Raises
    ------
    InputError
        Anything else, a name that is neither built in nor a file, an invalid file.
    """
    if isinstance(testbed, Testbed) or (optional and testbed is None):
        return testbed
    builtins = ", ".join(BUILTIN_TESTBEDS)
    if not _is_path(testbed):
        none = " or None" if optional else ""
        raise InputError(
            f"{name}={_short(testbed)}: expected {TESTBED_FORMS}{none} (built-in testbeds: "
            f"{builtins})"
        )
    if not (isinstance(testbed, str) and testbed in BUILTIN_TESTBEDS) and not os.path.isfile(
        testbed
    ):
        raise InputError(
            f"{name}={str(testbed)!r}: neither a built-in testbed name nor an existing testbed "
            f"file (built-in testbeds: {builtins})"
        )
    return load_testbed(testbed)


def check_log_testbed(testbed, log, what: str = "the testbed") -> None:
    """Refuse a log whose own testbed has another kind or dof than ``testbed``.

    A log read against an augmented copy of the same testbed (same kind and dof) and a log
    without a testbed pass.

    Parameters
    ----------
    testbed : Testbed
    log : Log
    what : str
        How the message names ``testbed`` (e.g. ``"the testbed to identify"``).
    """
    other = getattr(log, "testbed", None)
    if other is None or testbed is None:
        return
    if other.kind != testbed.kind or other.body.dof != testbed.body.dof:
        raise InputError(
            f"{log.source}: the log belongs to testbed {other.name!r} (kind = {other.kind!r}, "
            f"dof = {other.body.dof}), but {what} {testbed.name!r} has kind = "
            f"{testbed.kind!r}, dof = {testbed.body.dof}"
        )


def check_gyro_agrees(log) -> None:
    """Refuse a log whose gyro disagrees with its attitude (a dead, reversed, mis-scaled or
    saturated axis: :mod:`airbearing.io.gyro_check`): a fit on it is confidently wrong."""
    why = log.quality.gyro_disagreement
    if why:
        raise InputError(f"{log.source}: {why[0]}")


def as_log(log, testbed=None, *, columns=None, name: str = "log", what: str = "the testbed"):
    """A :class:`~airbearing.io.log.Log` from itself or a file, checked against ``testbed``."""
    # io.log loads pandas (0.5 s CPU): the testbed and number coercions of models/ and
    # design/ never need it
    from airbearing.io.log import Log, read_log

    if isinstance(log, Log):
        check_log_testbed(testbed, log, what)
        return log
    if not _is_path(log):
        raise InputError(f"{name}={_short(log)}: expected {LOG_FORMS}")
    return read_log(log, testbed, columns=columns)


def as_logs(
    logs,
    testbed=None,
    columns=None,
    *,
    name: str = "logs",
    what: str = "the testbed",
    allow_empty: bool = False,
) -> list:
    """A list of :class:`~airbearing.io.log.Log` from one log or file, or a list of them.

    Files are read with ``testbed`` (``columns``: :func:`~airbearing.io.log.read_log`);
    Log objects are checked against it (:func:`check_log_testbed`).

    Raises
    ------
    InputError
        None or another type, an element that is not a log or a path, no log at all
        (unless ``allow_empty``), a log of another kind of testbed.
    """
    from airbearing.io.log import Log  # pandas: see as_log

    if isinstance(logs, Log) or _is_path(logs):
        logs = [logs]
    if isinstance(logs, Mapping) or not isinstance(logs, Iterable):
        raise InputError(f"{name}={_short(logs)}: expected {LOG_FORMS}, or a list of them")
    out = [
        as_log(log, testbed, columns=columns, name=f"{name}[{i}]", what=what)
        for i, log in enumerate(logs)
    ]
    if not out and not allow_empty:
        raise InputError(f"{name}: expected at least one log, got none")
    return out


def as_float(
    value,
    name: str,
    unit: str = "",
    *,
    positive: bool = False,
    minimum: float | None = None,
    optional: bool = False,
    expected: str | None = None,
) -> float | None:
    """A finite real number (``positive``: > 0; ``minimum``: >= it), or an InputError.

    ``expected`` replaces the message's description of the accepted values.
    """
    if optional and value is None:
        return None
    what = "a positive" if positive else "a finite"
    if minimum is not None:
        what = f"a finite number >= {minimum:g}" + (f" {unit}" if unit else "")
    else:
        what = f"{what} number" + (f" in {unit}" if unit else "")
    what = expected or what
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise InputError(f"{name}={_short(value)}: expected {what}")
    x = float(value)
    if not math.isfinite(x) or (positive and x <= 0) or (minimum is not None and x < minimum):
        raise InputError(f"{name}={_short(value)}: expected {what}")
    return x


def as_int(value, name: str, *, minimum: int | None = None, optional: bool = False) -> int | None:
    """An integer (``minimum``: >= it), or an InputError; a float is not an integer."""
    if optional and value is None:
        return None
    ok = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if not ok or (minimum is not None and value < minimum):
        bound = "" if minimum is None else f" >= {minimum}"
        raise InputError(f"{name}={_short(value)}: expected an integer{bound}")
    return int(value)


def as_vector(value, name: str, size: int, what: str) -> np.ndarray:
    """``size`` finite real numbers (a sequence), or an InputError naming ``what``."""
    try:
        if isinstance(value, str | bytes | Mapping):
            raise TypeError
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        v = None
    if v is None or v.shape != (size,) or not np.all(np.isfinite(v)):
        raise InputError(f"{name}={_short(value)}: expected {what}")
    return v


def as_gains(gains, names: tuple[str, ...], name: str = "gains") -> np.ndarray:
    """Gains from a mapping by name or a sequence in the order of ``names``; finite, >= 0.

    Parameters
    ----------
    gains : mapping or sequence of float
        E.g. ``{"K_p": 6.0, "K_i": 0.001, "K_w": 6.0}`` (``TuningResult.gains``) or
        ``(6.0, 0.001, 6.0)``.
    names : tuple of str
        The gains in order.

    Returns
    -------
    ndarray (len(names),)
    """
    expected = f"a dict with keys {', '.join(names)} or a sequence of {len(names)} numbers"
    if isinstance(gains, Mapping):
        unknown = [k for k in gains if k not in names]
        missing = [k for k in names if k not in gains]
        if unknown or missing:
            what = f"unknown {unknown}" if unknown else f"missing {missing}"
            raise InputError(f"{name}: {what}; expected {expected}")
        values = [gains[k] for k in names]
    elif isinstance(gains, str | bytes) or not isinstance(gains, Iterable):
        raise InputError(f"{name}={_short(gains)}: expected {expected}")
    else:
        values = list(gains)
        if len(values) != len(names):
            raise InputError(f"{name}={_short(gains)}: expected {expected}")
    out = np.empty(len(names))
    for i, (k, v) in enumerate(zip(names, values, strict=True)):
        out[i] = as_float(v, f"{name}[{k!r}]", minimum=0.0)
    return out


def as_names(
    value,
    name: str,
    *,
    optional: bool = False,
    choices: Iterable[str] | None = None,
    kind: str = "name",
) -> list[str] | None:
    """A list of names from one string (one name) or an iterable of strings.

    ``choices``: the names allowed (an unknown one is an InputError listing them, calling
    it an unknown ``kind``).
    """
    if optional and value is None:
        return None
    if isinstance(value, str):
        out = [value]
    elif isinstance(value, Mapping) or not isinstance(value, Iterable):
        raise InputError(f"{name}={_short(value)}: expected a name or a list of names")
    else:
        out = list(value)
    bad = [v for v in out if not isinstance(v, str)]
    if bad:
        raise InputError(f"{name}: expected names (str), got {_short(bad[0])}")
    if choices is not None:
        allowed = list(choices)
        unknown = [v for v in out if v not in allowed]
        if unknown:
            raise InputError(
                f"{name}={_short(unknown[0])}: unknown {kind}; expected one of {', '.join(allowed)}"
            )
    return out


def as_effects(effects, name: str = "effects") -> dict | None:
    """Effects ``name -> value`` (FORMATS.md names and units) checked, or None."""
    if effects is None:
        return None
    if not isinstance(effects, Mapping):
        raise InputError(
            f"{name}={_short(effects)}: expected a dict of effect names to values "
            "(e.g. {'viscous_friction': 1e-4})"
        )

    for k, v in effects.items():
        if isinstance(v, np.ndarray | np.generic):  # numpy values as the vocabulary's types
            v = v.tolist()
        validate_effect_value(k, v, f"{name}[{k!r}]")
    return dict(effects)


def _short(value) -> str:
    """``repr`` of a value, cut to a readable length for a one-line message."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
