"""Plot of a log: its channels against time, gaps shaded, outliers marked.

Used by ``airbearing log plot``; the only module of the ``log`` command that imports
matplotlib.
"""

from __future__ import annotations

import numpy as np

from airbearing.io.log import Log
from airbearing.io.quality import LogQuality
from airbearing.reporting.html import Report, figure_html, plt

__all__ = ["log_figure", "log_report_html"]

# (title, columns, y label, scale to the plotted unit)
_PANELS: tuple[tuple[str, tuple[str, ...], str, float], ...] = (
    ("attitude quaternion", ("qw", "qx", "qy", "qz"), "quaternion component (-)", 1.0),
    ("yaw", ("yaw",), "yaw angle (deg)", 180.0 / np.pi),
    ("angular rate", ("wx", "wy", "wz"), "angular rate, body axes (deg/s)", 180.0 / np.pi),
    ("slider positions", ("s1", "s2", "s3"), "slider position along its rail (mm)", 1e3),
    ("magnetorquer dipole", ("mx", "my", "mz"), "commanded dipole, body axes (A m^2)", 1.0),
    ("magnetic field", ("bx", "by", "bz"), "magnetic field, body axes (uT)", 1e6),
    ("gimbal angles", ("d1", "d2", "d3", "d4"), "gimbal angle (deg)", 180.0 / np.pi),
    ("gimbal rates", ("dd1", "dd2", "dd3", "dd4"), "commanded gimbal rate (deg/s)", 180.0 / np.pi),
)


def log_figure(log: Log, quality: LogQuality | None = None, *, title: str | None = None):
    """A figure of every logged channel against time.

    Parameters
    ----------
    log : Log
    quality : LogQuality or None
        If given, gaps between segments are shaded grey and outlier samples are
        circled in red on every channel they concern.
    title : str or None
        Figure title (default: the log's source).

    Returns
    -------
    matplotlib.figure.Figure
        One panel per channel group present (attitude, rates, sliders, ...), time
        in s on the shared x axis, each y axis labelled in words with its unit.
    """
    panels = [p for p in _PANELS if log.has(*p[1])]
    if log.testbed is not None and not log.testbed.sensors.gyro:
        panels = [p for p in panels if p[0] != "angular rate"]
    t = log.t
    fig, axes = plt.subplots(
        max(len(panels), 1), 1, sharex=True, figsize=(9, 2.3 * max(len(panels), 1) + 0.6)
    )
    axes = np.atleast_1d(axes)
    outlier_cols: dict[int, tuple[str, ...]] = {}
    if quality is not None:
        outlier_cols = {o.row: o.columns for o in quality.outliers}
    for ax, (name, cols, label, factor) in zip(axes, panels, strict=False):
        for c in cols:
            ax.plot(t, log.column(c) * factor, lw=0.8, label=c)
        if quality is not None:
            for (_, b), (a2, _) in zip(quality.segments[:-1], quality.segments[1:], strict=True):
                ax.axvspan(t[b - 1], t[a2], color="0.85", zorder=0)
            for row, ocols in outlier_cols.items():
                for c in cols:
                    if c in ocols:
                        ax.plot(
                            t[row], log.column(c)[row] * factor, "o", mfc="none", mec="red", ms=8
                        )
        ax.set_ylabel(label)
        ax.set_title(name, fontsize=10, loc="left")
        ax.legend(loc="upper right", fontsize=8, ncol=len(cols))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    note = ""
    if quality is not None:
        note = (
            f" — {quality.n_segments} segment(s) (gaps shaded), "
            f"{len(quality.outlier_rows)} outlier row(s) (red circles)"
        )
    fig.suptitle((title or log.source) + note, fontsize=10)
    return fig


def log_report_html(log: Log, quality: LogQuality | None = None) -> str:
    """A self-contained HTML page with :func:`log_figure` and the outlier table."""
    report = Report(f"Log {log.source}")
    report.raw(figure_html(log_figure(log, quality), "Logged channels against time."))
    if quality is not None:
        report.paragraph(
            f"{log.n} rows, {quality.n_segments} segment(s), jitter {quality.jitter:.3f}, "
            f"outlier rows: {', '.join(map(str, quality.outlier_rows)) or 'none'}."
        )
        if quality.outliers:
            report.table(
                [
                    {
                        "row": o.row,
                        "t (s)": o.t,
                        "columns": ", ".join(o.columns),
                        "reason": o.reason,
                    }
                    for o in quality.outliers
                ]
            )
    return report.html()
