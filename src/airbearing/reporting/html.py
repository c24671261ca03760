"""Self-contained HTML reports: figures embedded as base64 SVG/PNG, no network.

Every report of the package (demo, stability report, discrepancy report) is built
from :class:`Report` so they look alike and print alike.
"""

from __future__ import annotations

import base64
import html
import io
import math
import re
from dataclasses import dataclass, field

import matplotlib

from airbearing.io.output import write_atomic, write_json  # noqa: F401  (re-exported)
from airbearing.io.units import split_unit

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

__all__ = [
    "EXPECTED_KEY",
    "Report",
    "figure_html",
    "table_html",
    "write_atomic",
    "write_json",
    "NONE_TEXT",
    "column_label",
    "sentence",
]

#: What a table shows for a value that does not exist (None, NaN); a legend says so.
NONE_TEXT = "—"
#: Texts other code uses for "no value"; a table shows :data:`NONE_TEXT` for each.
_MISSING_TEXTS = frozenset({"", "-", "–", "—", "nan", "NaN", "None", "none", "n/a", "N/A"})
#: Columns whose True/False is a verdict (pass/FAIL); other booleans print yes/no.
_VERDICT_WORDS = ("ok", "met", "pass", "stable", "verdict")


_CSS = """
body { font-family: system-ui, -apple-system, Segoe UI, Roboto, sans-serif; margin: 2em auto;
       max-width: 1100px; color: #222; line-height: 1.45; padding: 0 1em;
       overflow-wrap: break-word; }
h1 { border-bottom: 2px solid #345; padding-bottom: .2em; }
h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
.scroll { overflow-x: auto; max-width: 100%; margin: 1em 0; }
.scroll table { margin: 0; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.92em; }
p.legend { font-size: 0.85em; color: #555; margin-top: -0.5em; }
th, td { border: 1px solid #bbb; padding: 4px 8px; text-align: right; }
th { background: #eef2f5; }
td.l { white-space: nowrap; }
td.l, th.l { text-align: left; }
.pass { color: #11772d; font-weight: 600; }
.fail { color: #b00020; font-weight: 600; }
.fail-expected { color: #8a5a00; font-weight: 600; }
figure { margin: 1em 0; page-break-inside: avoid; }
figure img { max-width: 100%; height: auto; }
figcaption { font-size: 0.9em; color: #555; }
.note { background: #f6f8fa; border-left: 4px solid #345; padding: .5em 1em; }
@media print { body { max-width: none; margin: 0; } h2 { page-break-before: auto; } }
"""


def figure_html(fig, caption: str = "", *, fmt: str = "svg") -> str:
    """Embed a matplotlib figure as a base64 ``<img>`` and close it.

    Figures without a layout engine get matplotlib's constrained layout (no label of
    one panel over its neighbour) and aligned y-labels.
    """
    try:
        if fig.get_layout_engine() is None:
            fig.set_layout_engine("constrained")
        fig.align_ylabels()
    except (AttributeError, RuntimeError, ValueError):  # pragma: no cover - old matplotlib
        pass
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, bbox_inches="tight", dpi=110)
    plt.close(fig)
    mime = "image/svg+xml" if fmt == "svg" else "image/png"
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    cap = f"<figcaption>{html.escape(sentence(caption))}</figcaption>" if caption else ""
    return (
        f'<figure><img alt="{html.escape(caption)}" src="data:{mime};base64,{data}"/>{cap}</figure>'
    )


def column_label(name: str) -> str:
    """A column name for people: ``final_Hx_h0`` -> ``final Hx / h0``, ``t_peak_s`` ->
    ``t peak (s)``; a name with a space (already for people) is kept."""
    if " " in name or "_" not in name:
        return name
    stem, unit = split_unit(name)
    if unit == "m" and "_" not in stem:
        unit = ""  # min_m: the manipulability m, not metres
    else:
        name = stem
    parts = name.split("_")
    if len(parts) > 2 and re.fullmatch(r"[a-z]\w*0", parts[-1]):  # normalised by h0, J0, ...
        text = " ".join(parts[:-1]) + " / " + parts[-1]
    else:
        text = " ".join(parts)
    return f"{text} ({unit})" if unit else text


def pretty_key(key: str) -> str:
    """A JSON key or result column as a header: ``gain_margin_db`` -> ``gain margin (dB)``,
    ``gimbal_min_deg[0]`` -> ``gimbal min [0] (deg)``."""
    index = ""
    if key.endswith("]") and "[" in key:
        key, index = key[: key.index("[")], " " + key[key.index("[") :]
    stem, unit = split_unit(key)
    text = stem.replace("_", " ") + index
    return f"{text} ({unit})" if unit else text


def sentence(text: str) -> str:
    """``text`` ending as a sentence (a full stop added unless it ends in . ! ? or :)."""
    text = str(text).strip()
    return text if not text or text[-1] in ".!?:" else text + "."


def _fmt(v) -> str:
    """A cell: 4 significant digits; no 'nan'/'inf' text (none, infinity sign)."""
    if v is None:
        return NONE_TEXT
    if isinstance(v, float) or (hasattr(v, "dtype") and hasattr(v, "item")):
        try:
            f = float(v)
        except (TypeError, ValueError):
            return html.escape(str(v))
        if math.isnan(f):
            return NONE_TEXT
        if math.isinf(f):
            return "∞" if f > 0 else "−∞"
        return f"{f:.4g}"
    if isinstance(v, str) and v.strip() in _MISSING_TEXTS:
        return NONE_TEXT
    return html.escape(str(v))


#: Column of a table row saying why a FAIL in that row is expected ("" or absent: not).
EXPECTED_KEY = "failure expected because"


def _is_verdict(column: str) -> bool:
    words = column.lower().replace("(", " ").replace(")", " ").split()
    return any(w in _VERDICT_WORDS for w in words)


def table_html(
    rows: list[dict], columns: list[str] | None = None, *, classes=None, legend: str | None = None
) -> str:
    """A table from a list of dicts, in a wrapper that scrolls sideways when it is wide.

    First column left-aligned. A value that does not exist (None, NaN) prints as
    :data:`NONE_TEXT` and the table gets a legend saying what that means (``legend``,
    default "not defined"). True/False print as pass/FAIL in verdict columns (names with
    "ok", "met", "pass", "stable") and as yes/no elsewhere; a FAIL whose row says why it is
    expected (a non-empty :data:`EXPECTED_KEY`) prints as "FAIL, expected" (class
    ``fail-expected``, which a summary counts apart from an unexpected ``fail``).
    """
    if not rows:
        return "<p><em>(empty)</em></p>"
    columns = columns or list(rows[0])
    head = "\n".join(
        f'<th class="{"l" if i == 0 else ""}">{html.escape(column_label(str(c)))}</th>'
        for i, c in enumerate(columns)
    )
    body = []
    used_none = False
    for r in rows:
        cells = []
        for i, c in enumerate(columns):
            v = r.get(c, "")
            cls = "l" if i == 0 else ""
            if isinstance(v, bool) or type(v).__name__ == "bool_":
                if _is_verdict(c) and not v and r.get(EXPECTED_KEY):
                    cls, v = "fail-expected", "FAIL, expected"
                elif _is_verdict(c):
                    cls, v = ("pass", "pass") if v else ("fail", "FAIL")
                else:
                    v = "yes" if v else "no"
            text = _fmt(v)
            used_none = used_none or text == NONE_TEXT
            cells.append(f'<td class="{cls}">{text}</td>')
        body.append("<tr>" + "\n".join(cells) + "</tr>")
    note = ""
    if used_none:
        note = f'<p class="legend">{NONE_TEXT}: {html.escape(legend or "not defined")}.</p>'
    rows_html = "\n".join(body)
    return f'<div class="scroll"><table>\n<tr>{head}</tr>\n{rows_html}\n</table></div>{note}'


@dataclass
class Report:
    """An HTML report built section by section."""

    title: str
    parts: list[str] = field(default_factory=list)

    def heading(self, text: str, level: int = 2) -> None:
        self.parts.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def paragraph(self, text: str, *, note: bool = False) -> None:
        cls = ' class="note"' if note else ""
        self.parts.append(f"<p{cls}>{html.escape(sentence(text))}</p>")

    def figure(self, fig, caption: str = "") -> None:
        self.parts.append(figure_html(fig, caption))

    def table(
        self, rows: list[dict], columns: list[str] | None = None, *, legend: str | None = None
    ) -> None:
        self.parts.append(table_html(rows, columns, legend=legend))

    def raw(self, fragment: str) -> None:
        self.parts.append(fragment)

    def html(self) -> str:
        return (
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'/>"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1>" + "\n".join(self.parts) + "</body></html>"
        )

    def write(self, path) -> None:
        """Write the report atomically (commands queue :meth:`html` in their Outputs)."""
        write_atomic(path, self.html())
