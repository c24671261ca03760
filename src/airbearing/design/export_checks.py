"""The checks of an export's inputs: a C identifier for the files and symbols, and the gains
of a loop (finite numbers >= 0, by name or in order)."""

from __future__ import annotations

import math
import re

from airbearing.errors import InputError

_C_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto "
    "if inline int long register restrict return short signed sizeof static struct switch "
    "typedef union unsigned void volatile while _Bool _Complex _Imaginary".split()
)


def check_c_name(name: str) -> str:
    """``name`` if it is a C identifier (and no keyword), else an InputError."""
    if not isinstance(name, str) or not _C_NAME.match(name) or name in _C_KEYWORDS:
        raise InputError(
            f"name {name!r}: expected a C identifier (letters, digits, _; not starting with a "
            "digit; no C keyword)"
        )
    return name


def _gain_values(names, gains, loop: str) -> dict:
    """``gains`` (a mapping by name or a sequence in order) as a dict of finite numbers >= 0."""
    if isinstance(gains, dict):
        unknown = [k for k in gains if k not in names]
        missing = [k for k in names if k not in gains]
        if unknown or missing:
            raise InputError(
                f"gains {sorted(gains)} do not fit the {loop} loop: expected {list(names)}"
            )
        vals = [gains[k] for k in names]
    else:
        vals = list(gains)
        if len(vals) != len(names):
            raise InputError(f"gains {vals}: the {loop} loop takes {len(names)}, {list(names)}")
    out = {}
    for k, v in zip(names, vals, strict=True):
        try:
            v = float(v)
        except (TypeError, ValueError):
            v = math.nan
        if not (math.isfinite(v) and v >= 0):
            raise InputError(f"gains {k}={vals[names.index(k)]!r}: expected a finite number >= 0")
        out[k] = v
    return out
