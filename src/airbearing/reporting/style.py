"""How the report figures draw a trace, label an axis and place a legend.

- A trace is a thin line with a few markers (every ``len / MARKS`` samples), so a fast
  oscillation (a dithered steering law's singularity measure) reads as a line whose
  law is told by its marker, not as a solid band that hides the others.
- Tick labels never use matplotlib's offset text ("1e-10+5.729577951e1").
- An axis named by a result key says it in words with its unit (``peak_rate_deg_s`` ->
  "peak rate (deg/s)", :func:`airbearing.reporting.html.pretty_key`).
"""

from __future__ import annotations

import numpy as np
from matplotlib.ticker import MaxNLocator

from airbearing.reporting.html import pretty_key

__all__ = ["trace", "chatters", "plain", "axis_label", "legend_outside", "MARKERS", "MARKS"]

#: One marker per trace of a panel, in order.
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
#: About this many markers along a trace.
MARKS = 16


def trace(ax, x, y, label: str | None = None, k: int = 0, **kw):
    """Plot ``y`` against ``x`` as a thin line with decimated markers (trace ``k``)."""
    n = len(np.asarray(x))
    opts = {
        "lw": 0.9,
        "marker": MARKERS[k % len(MARKERS)],
        "markevery": max(n // MARKS, 1),
        "ms": 4,
        "mfc": "none",
    }
    opts.update(kw)
    x, y = np.asarray(x), np.asarray(y)
    if chatters(y):
        # a line joining samples that jump between two levels fills a band and hides the
        # other traces: every few samples as a marker shows both levels
        step = max(n // 120, 1)
        opts.update(ls="none", markevery=None, ms=3)
        (line,) = ax.plot(x[::step], y[::step], label=f"{label} (chatters: samples)", **opts)
        return line
    (line,) = ax.plot(x, y, label=label, **opts)
    return line


def chatters(y, share: float = 0.1) -> bool:
    """Whether ``y`` turns back at more than ``share`` of its samples (a sample-to-sample
    chatter) by steps of at least 1 % of its range."""
    y = np.asarray(y, dtype=float)
    y = y[np.isfinite(y)]
    if y.size < 20:
        return False
    d = np.diff(y)
    # a turn counts when its step is visible: 1 % of the trace's range (not roundoff)
    big = np.abs(d) > 1e-2 * max(float(np.ptp(y)), 1e-300)
    turns = np.sum((d[1:] * d[:-1] < 0) & big[1:] & big[:-1])
    return bool(turns > share * (y.size - 2))


def plain(ax, *, ticks: int | None = None) -> None:
    """No offset text on the axes' tick labels; at most ``ticks`` ticks on x (crowded panels)."""
    for axis in ("x", "y"):
        try:
            ax.ticklabel_format(axis=axis, useOffset=False)
        except AttributeError:  # a log or categorical axis has no offset
            pass
    if ticks is not None and ax.get_xscale() == "linear":
        ax.xaxis.set_major_locator(MaxNLocator(ticks))


def axis_label(key: str) -> str:
    """A result key in words with its unit: ``peak_rate_deg_s`` -> "peak rate (deg/s)"."""
    key = str(key)
    if key.startswith("effects."):
        return f"{key.split('.', 1)[1].replace('_', ' ')} (FORMATS.md unit)"
    return pretty_key(key.replace(".", " "))


def legend_outside(ax, **kw) -> None:
    """A legend to the right of the axes, never over the data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0, **kw)
