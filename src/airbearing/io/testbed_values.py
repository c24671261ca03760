"""The value checks of a testbed file: each takes the value, the source and the dotted key.

A check returns the value normalised (a float, a tuple of floats, a nested tuple) or
raises :class:`~airbearing.errors.InputError` with one line naming the source (a file, a
built-in or ``"<memory>"``), the dotted key (``body.mass``) and what was expected, e.g.
``bench.toml: key 'body.mass': expected a finite number > 0 (kg), got -1.0``. The tables
that use them are in :mod:`airbearing.io.testbed_tables`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from airbearing.errors import InputError

#: The source named in messages about a testbed built in memory (not read from a file).
_MEMORY = "<memory>"
_SYMMETRY_RTOL = 1e-9  # relative tolerance of the inertia symmetry check


def _is_number(value: object) -> bool:
    """True for int and float (numpy scalars included); booleans are not numbers."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def _fail(src: str, key: str, expected: str, got: object) -> InputError:
    shown = str(got).lower() if isinstance(got, bool) else repr(got)  # TOML's true/false
    return InputError(f"{src}: key '{key}': expected {expected}, got {shown}")


def _number(
    value: object,
    src: str,
    key: str,
    unit: str,
    *,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    allow_inf: bool = False,
) -> float:
    """A float from an int or float (not a bool), finite unless allowed, within bounds."""
    bounds = []
    if gt is not None:
        bounds.append(f"> {gt:g}")
    if ge is not None:
        bounds.append(f">= {ge:g}")
    if lt is not None:
        bounds.append(f"< {lt:g}")
    if le is not None:
        bounds.append(f"<= {le:g}")
    what = "a " + ("" if allow_inf else "finite ") + "number"
    if bounds:
        what += " " + " and ".join(bounds)
    if unit:
        what += f" ({unit})"
    if not _is_number(value):
        raise _fail(src, key, what, value)
    x = float(value)  # type: ignore[arg-type]
    if math.isnan(x) or (math.isinf(x) and not allow_inf):
        raise _fail(src, key, what, value)
    if (
        (gt is not None and not x > gt)
        or (ge is not None and not x >= ge)
        or (lt is not None and not x < lt)
        or (le is not None and not x <= le)
    ):
        raise _fail(src, key, what, value)
    return x


def _vector(value: object, n: int, src: str, key: str, unit: str) -> tuple[float, ...]:
    """A tuple of n finite floats."""
    what = f"a list of {n} finite numbers ({unit})"
    if not isinstance(value, list | tuple | np.ndarray) or len(value) != n:
        raise _fail(src, key, what, value)
    out = []
    for v in value:
        if not _is_number(v) or not math.isfinite(float(v)):
            raise _fail(src, key, what, value)
        out.append(float(v))
    return tuple(out)


def _vector3(value: object, src: str, key: str, unit: str) -> tuple[float, float, float]:
    x, y, z = _vector(value, 3, src, key, unit)
    return (x, y, z)


def _matrix3(value: object, src: str, key: str, what: str) -> tuple[tuple[float, ...], ...]:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise _fail(src, key, what, value)
    rows = []
    for row in value:
        if isinstance(row, np.ndarray):
            row = row.tolist()
        if not isinstance(row, list | tuple) or len(row) != 3:
            raise _fail(src, key, what, value)
        if not all(_is_number(v) and math.isfinite(float(v)) for v in row):
            raise _fail(src, key, what, value)
        rows.append(tuple(float(v) for v in row))
    return tuple(rows)


def _inertia(value: object, dof: int, src: str, key: str) -> float | tuple[tuple[float, ...], ...]:
    """Scalar yaw inertia (dof 1 only) or a symmetric positive definite 3x3 matrix."""
    if _is_number(value):
        if dof != 1:
            raise _fail(
                src,
                key,
                "a symmetric 3x3 matrix (kg m^2) for dof = 3 (a single number is "
                "accepted only for dof = 1)",
                value,
            )
        return _number(value, src, key, "kg m^2", gt=0.0)
    what = "a symmetric positive definite 3x3 matrix (kg m^2)"
    if dof == 1:
        what = "a positive number or " + what
    matrix = _matrix3(value, src, key, what)
    m = np.array(matrix)
    scale = float(np.max(np.abs(m)))
    if float(np.max(np.abs(m - m.T))) > _SYMMETRY_RTOL * scale:
        raise _fail(src, key, "a symmetric 3x3 matrix (kg m^2)", value)
    eigenvalues = np.linalg.eigvalsh(0.5 * (m + m.T))
    if not np.all(eigenvalues > 0.0):
        raise InputError(
            f"{src}: key '{key}': expected a positive definite 3x3 matrix (kg m^2), "
            f"got {value!r} with eigenvalues {eigenvalues.tolist()!r}"
        )
    return matrix


def _integer_choice(value: object, choices: tuple[int, ...], src: str, key: str) -> int:
    what = "one of " + ", ".join(str(c) for c in choices)
    if isinstance(value, np.integer):
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool) or value not in choices:
        raise _fail(src, key, what, value)
    return value


def _boolean(value: Any, src: str, key: str) -> bool:
    if not isinstance(value, bool):
        raise _fail(src, key, "true or false", value)
    return value
