"""Human output of the commands: aligned plain-text tables with units, 4 significant digits.

JSON outputs keep full precision; these tables are for reading at the bench. No numpy
at import time (start-up).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence

import typer

from airbearing.io.units import split_unit

__all__ = [
    "cell",
    "table",
    "summary_table",
    "echo_table",
    "echo_summary",
    "unit_of",
    "shown",
    "human_summary",
    "matrix_table",
    "tidy_numbers",
]

#: Units of JSON keys named without a unit suffix.
_KEY_UNITS = {"dipole_rms": "A m^2"}  # magnetorquer dipole (seed 000)

#: Words for JSON keys whose name alone reads as code (the two-step's ``ke_rates``,
#: ``in_plane_known``); the JSON keeps its keys.
_LABELS = {
    # the two-step's E = w^T J w, seed 004 eq. 53 as written: twice the kinetic energy
    "ke_std_before": "std of E = w^T J w before",
    "ke_std_after": "std of E = w^T J w after",
    "ke_reduction": "reduction of std E",
    "ke_rates": "E from",
    "ke_std_before_measured": "std of E before, measured",
    "ke_std_after_measured": "std of E after, measured",
    "ke_reduction_measured": "reduction of std E, measured",
    "ke_noise_floor": "noise floor of measured std E",
    "ke_measured_from": "measured E from",
    "in_plane_known": "in-plane offset of step 1 used",
    "identify_method": "identification method",
    "identify_warnings": "identification warnings",
    "iterations": "identification rounds",
    "g_perp_rms_step1": "g perp rms, step 1",
    "balance_duration_s": "step 1 duration",
    "sliders_step1_m": "sliders after step 1",
    "residual_offset_step1_m": "residual offset after step 1",
    "vertical_offset_estimates_m": "vertical offset, each round",
    "sliders_final_unrounded_m": "sliders final, unrounded",
    "drift_p_g": "drift p-value of g",
    "drift_p_stepper": "drift p-value of the steppers",
}
#: Values that read as code, in words, by key.
_VALUES = {
    "ke_rates": {"true": "true rates (simulation)", "measured": "measured rates"},
    "ke_measured_from": {"gyro": "gyro rates", "attitude": "attitude derivative"},
}


def unit_of(key: str) -> tuple[str, str]:
    """``(label, unit)`` of a JSON key named with a unit suffix (``t_peak_s`` -> ``t peak``, s)."""
    label, unit = _unit_of(key)
    return _LABELS.get(key, label), unit


def _unit_of(key: str) -> tuple[str, str]:
    if key in _KEY_UNITS:
        return key.replace("_", " "), _KEY_UNITS[key]
    stem, unit = split_unit(key)
    return stem.replace("_", " "), unit


#: A number written with more digits than a person reads (``-3.690476190476191e-05``).
_LONG_NUMBER = re.compile(r"(?<![\w.])-?\d+\.\d{5,}(?:e[+-]?\d+)?(?![\w.])")


def tidy_numbers(text: str, digits: int = 4) -> str:
    """``text`` with its long numbers at ``digits`` significant digits (a library's
    sentence that quotes a value: ``offset [-3.69e-05, ...] m``)."""
    return _LONG_NUMBER.sub(lambda m: cell(float(m.group()), digits), str(text))


#: Lengths in the unit a person uses: CM offsets and residual offsets in um (they are
#: um to tenths of mm), slider positions and displacements in mm. (words in key, unit, x)
_LENGTHS = (
    (("offset", "residual", "cm_"), "um", 1e6),
    (("slider", "displacement", "p2p", "travel"), "mm", 1e3),
)


def shown(key: str, value):
    """``(label, unit, value)`` for a person: SI lengths of key suffix ``_m`` rescaled.

    ``cm_offset_identified_m`` -> ``("cm offset identified", "um", value * 1e6)``; other
    keys as :func:`unit_of`. Lists and nested lists are rescaled element by element.
    """
    label, unit = unit_of(key)
    if not unit and key.startswith(("ke_std", "ke_noise")):
        unit = "J"  # spreads of E = w^T J w (seed 004 eqs. 53-54), twice the kinetic energy
    if unit == "m":
        low = key.lower()
        for words, new, factor in _LENGTHS:
            if any(w in low for w in words):
                return label, new, _scale(value, factor)
    return label, unit, value


def _scale(value, factor: float):
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, int | float):
        return value * factor
    if isinstance(value, list | tuple):
        return [_scale(v, factor) for v in value]
    return value


def _is_vector(value) -> bool:
    return (
        isinstance(value, list | tuple)
        and 1 < len(value) <= 4
        and all(isinstance(v, int | float) and not isinstance(v, bool) or v is None for v in value)
    )


def _is_matrix(value) -> bool:
    return (
        isinstance(value, list | tuple)
        and len(value) in (2, 3)
        and all(_is_vector(r) and len(r) == len(value) for r in value)
    )


def matrix_table(rows, unit: str = "", names=("x", "y", "z"), std=None, digits: int = 4) -> str:
    """A square matrix as an aligned table (4 significant digits, ``+-std`` if given)."""
    body = []
    for i, row in enumerate(rows):
        cells = []
        for j, v in enumerate(row):
            text = cell(v, digits)
            if std is not None and std[i][j] is not None and std[i][j] == std[i][j]:
                text += f" +-{float(std[i][j]):.2g}"
            cells.append(text)
        body.append([names[i] if i < len(names) else str(i), *cells])
    head = f"({unit})" if unit else ""
    return table(body, [head, *(names[j] for j in range(len(rows)))], digits)


def human_summary(summary: Mapping, skip: Iterable[str] = (), digits: int = 4) -> str:
    """A JSON summary for a person: scalars as one aligned table, vectors as x y z rows,
    matrices as aligned blocks, small mappings as their own tables, text lists as lines.

    Units come from the key suffix; CM offsets are shown in um and sliders in mm
    (:func:`shown`); the JSON keeps SI.
    """
    skip = set(skip)
    scalars, vectors, blocks, sentences = [], [], [], []
    for key, value in summary.items():
        if key in skip:
            continue
        label, unit, v = shown(key, value)
        if isinstance(v, str) and v in _VALUES.get(key, {}):
            v = _VALUES[key][v]
        if _is_matrix(v):
            blocks.append(f"{label}:\n" + matrix_table(v, unit, digits=digits))
        elif _is_vector(v):
            vectors.append([label, *[cell(x, digits) for x in v], unit, len(v)])
        elif isinstance(v, Mapping):
            if v and all(not isinstance(x, Mapping | list | tuple) for x in v.values()):
                of = v.get("of") if isinstance(v.get("of"), str) else None
                rows = [[shown(k, x)[0], cell(shown(k, x)[2], digits), shown(k, x)[1]]
                        for k, x in v.items() if not (of and k == "of")]  # fmt: skip
                head = f"{label} ({of})" if of else label  # ratios of mixed/mechanical
                blocks.append(f"{head}:\n" + table(rows, ["quantity", "value", "unit"]))
        elif isinstance(v, list | tuple) and all(isinstance(x, str) for x in v):
            if v:
                blocks.append(f"{label}:\n" + "\n".join(f"  - {tidy_numbers(x)}" for x in v))
            else:
                scalars.append([label, "none", unit])
        elif isinstance(v, list | tuple):
            continue  # long series: in the JSON
        elif isinstance(v, str) and len(v) > 40:
            sentences.append(f"{label}: {tidy_numbers(v, digits)}")
        elif isinstance(v, str) and unit:  # words in place of a number: no unit
            scalars.append([label, v, ""])
        else:
            scalars.append([label, cell(v, digits), unit])
    parts = []
    if scalars:
        parts.append(table(scalars, ["quantity", "value", "unit"], digits))
    if vectors:
        n = max(r[-1] for r in vectors)
        names = ["x", "y", "z", "4"][:n]
        rows = [[r[0], *r[1:-2], *[""] * (n - (len(r) - 3)), r[-2]] for r in vectors]
        parts.append(table(rows, ["vector", *names, "unit"], digits))
    parts.extend(blocks)
    parts.extend(sentences)
    return "\n\n".join(parts)


def cell(value, digits: int = 4) -> str:
    """One value as text: 4 significant digits (every integer digit from 1e4 to 1e9), ``—``
    for none, yes/no, lists space-separated."""
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
        if 10**digits <= abs(v) < 1e9:  # every integer digit: -19003 um, not -1.9e+04
            return f"{v + 0.0:.0f}"
        return f"{v + 0.0:.{digits}g}"  # + 0.0: no "-0"
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
    numeric = [
        all(_is_number(r[j]) or r[j] in ("—", "") for r in body)
        and any(_is_number(r[j]) for r in body)
        for j in range(cols)
    ]

    def line(items):
        out = [
            (it.rjust(w) if num else it.ljust(w))
            for it, w, num in zip(items, widths, numeric, strict=True)
        ]
        return "  ".join(out).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(list(headers)), rule, *(line(r) for r in body)])


def dict_table(rows: Sequence[Mapping]) -> str:
    """Rows of ``{key: value}`` as a :func:`table`, the unit in each column head from the
    key's suffix (``offset_mm`` -> ``offset (mm)``); empty text for no rows."""
    if not rows:
        return ""
    cols = list(rows[0])
    heads = []
    for c in cols:
        label, unit = unit_of(c)
        heads.append(f"{label} ({unit})" if unit else label)
    return table([[r.get(c) for c in cols] for r in rows], heads)


def _is_pairs(value) -> bool:
    return isinstance(value, Sequence) and all(
        isinstance(p, Sequence) and len(p) == 2 and all(isinstance(x, int) for x in p)
        for p in value
    )


def summary_table(summary: Mapping, skip: Iterable[str] = (), digits: int = 4) -> str:
    """A flat JSON summary as a ``quantity | value | unit`` table (units from key suffixes)."""
    skip = set(skip)
    rows = []
    for key, value in summary.items():
        if key in skip or isinstance(value, Mapping) and len(value) > 6:
            continue
        if isinstance(value, Sequence) and not isinstance(value, str) and len(value) > 8:
            continue
        label, unit, value = shown(key, value)
        if key.endswith("_rows") and _is_pairs(value):
            text = ", ".join(f"{a}-{b - 1}" for a, b in value) or "none"  # [start, stop)
        elif isinstance(value, Sequence) and not isinstance(value, str) and not value:
            text = "none"
        else:
            text = cell(value, digits)
        rows.append([label, text, unit])
    return table(rows, ["quantity", "value", "unit"], digits)


def echo_table(rows, headers, digits: int = 4) -> None:
    """Print :func:`table` on stdout."""
    typer.echo(table(rows, headers, digits))


def echo_summary(summary: Mapping, skip: Iterable[str] = (), digits: int = 4) -> None:
    """Print :func:`summary_table` on stdout."""
    typer.echo(summary_table(summary, skip, digits))
