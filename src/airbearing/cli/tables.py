"""Human output of the commands: aligned plain-text tables with units, 4 significant digits.

JSON outputs keep full precision; these tables are for reading at the bench. No numpy
at import time (start-up).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

import typer

__all__ = ["cell", "table", "summary_table", "echo_table", "echo_summary", "unit_of"]

#: Units taken from a key's suffix (the JSON contract's naming): ``peak_rate_deg_s`` -> deg/s.
_SUFFIX_UNITS = (
    ("_deg_s", "deg/s"),
    ("_rad_s", "rad/s"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_mm", "mm"),
    ("_um", "um"),
    ("_m", "m"),
    ("_s", "s"),
    ("_hz", "Hz"),
    ("_db", "dB"),
    ("_kg", "kg"),
    ("_nm", "N m"),
    ("_j", "J"),
)


def unit_of(key: str) -> tuple[str, str]:
    """``(label, unit)`` of a JSON key named with a unit suffix (``t_peak_s`` -> ``t peak``, s)."""
    low = key.lower()
    for suffix, unit in _SUFFIX_UNITS:
        if low.endswith(suffix) and len(low) > len(suffix):
            return key[: -len(suffix)].replace("_", " "), unit
    return key.replace("_", " "), ""


def cell(value, digits: int = 4) -> str:
    """One value as text: 4 significant digits, ``—`` for none, yes/no, lists space-separated."""
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float) or hasattr(value, "__float__") and not isinstance(value, str):
        try:
            v = float(value)
        except (TypeError, ValueError):
            return str(value)
        if math.isnan(v):
            return "—"
        if math.isinf(v):
            return "∞" if v > 0 else "-∞"
        return f"{v:.{digits}g}"
    if isinstance(value, Mapping):
        return ", ".join(f"{k} {cell(v, digits)}" for k, v in value.items())
    if isinstance(value, Sequence) and not isinstance(value, str):
        return " ".join(cell(v, digits) for v in value)
    return str(value)


def _is_number(text: str) -> bool:
    try:
        float(text.split()[0])
    except (ValueError, IndexError):
        return False
    return True


def table(rows: Iterable[Sequence], headers: Sequence[str], digits: int = 4) -> str:
    """Rows as an aligned text table (numbers right-aligned, text left-aligned)."""
    body = [[cell(v, digits) if not isinstance(v, str) else v for v in r] for r in rows]
    cols = len(headers)
    widths = [max([len(headers[j])] + [len(r[j]) for r in body]) for j in range(cols)]
    numeric = [all(_is_number(r[j]) or r[j] == "—" for r in body) and body for j in range(cols)]

    def line(items):
        out = [
            (it.rjust(w) if num else it.ljust(w))
            for it, w, num in zip(items, widths, numeric, strict=True)
        ]
        return "  ".join(out).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(list(headers)), rule, *(line(r) for r in body)])


def summary_table(summary: Mapping, skip: Iterable[str] = (), digits: int = 4) -> str:
    """A flat JSON summary as a ``quantity | value | unit`` table (units from key suffixes)."""
    skip = set(skip)
    rows = []
    for key, value in summary.items():
        if key in skip or isinstance(value, Mapping) and len(value) > 6:
            continue
        if isinstance(value, Sequence) and not isinstance(value, str) and len(value) > 8:
            continue
        label, unit = unit_of(key)
        rows.append([label, cell(value, digits), unit])
    return table(rows, ["quantity", "value", "unit"], digits)


def echo_table(rows, headers, digits: int = 4) -> None:
    """Print :func:`table` on stdout."""
    typer.echo(table(rows, headers, digits))


def echo_summary(summary: Mapping, skip: Iterable[str] = (), digits: int = 4) -> None:
    """Print :func:`summary_table` on stdout."""
    typer.echo(summary_table(summary, skip, digits))
