"""Plot of a log: its channels against time, gaps as breaks, glitches visible, outliers marked.

Used by ``airbearing log plot``; the only module of the ``log`` command that imports
matplotlib. What the figure shows so that a person sees the log's artefacts:

- a gap is a break in every line (a NaN between segments) and a shaded band, never a
  straight line drawn across it;
- yaw is plotted wrapped to (-180, 180] deg (a spinning rig's unwrapped yaw reaches
  tens of thousands of degrees, where an 8 deg glitch is invisible), with the yaw rate
  from the logged angle and the **residual from a local trend** (the sample minus the
  running median of its neighbours): a glitch stands out there without any marker;
- every label lies inside the figure (constrained layout; the CLI saves with a tight
  bounding box).
"""

from __future__ import annotations

import numpy as np

from airbearing.io.log import WHEEL_COMMAND_COLUMNS, WHEEL_SPEED_COLUMNS, Log, segments_of
from airbearing.io.quality import LogQuality
from airbearing.reporting.html import Report, figure_html, plt

__all__ = [
    "log_figure",
    "log_report_html",
    "with_breaks",
    "local_residual",
    "source_name",
    "TREND_WINDOW",
]

_DEG = 180.0 / np.pi
_RPM = 60.0 / (2.0 * np.pi)  # rad/s -> rpm
# (title, columns, y label, scale to the plotted unit)
_PANELS: tuple[tuple[str, tuple[str, ...], str, float], ...] = (
    ("attitude quaternion", ("qw", "qx", "qy", "qz"), "quaternion component (-)", 1.0),
    ("yaw", ("yaw",), "yaw angle (deg)", _DEG),
    ("angular rate", ("wx", "wy", "wz"), "angular rate, body axes (deg/s)", _DEG),
    ("slider positions", ("s1", "s2", "s3"), "slider position along its rail (mm)", 1e3),
    ("magnetorquer dipole", ("mx", "my", "mz"), "commanded dipole, body axes (A m^2)", 1.0),
    ("magnetic field", ("bx", "by", "bz"), "magnetic field, body axes (uT)", 1e6),
    ("gimbal angles", ("d1", "d2", "d3", "d4"), "gimbal angle (deg)", _DEG),
    ("gimbal rates", ("dd1", "dd2", "dd3", "dd4"), "commanded gimbal rate (deg/s)", _DEG),
)
#: Samples of the running median that defines the local trend (odd). A glitch of up to
#: (TREND_WINDOW - 1) / 2 consecutive samples does not move the median, so the residual
#: shows it whole; a smooth motion (monotonic over the window, as a spin is) has a
#: residual of the noise only.
TREND_WINDOW = 9


def _segments(log: Log, quality: LogQuality | None) -> tuple[tuple[int, int], ...]:
    if quality is not None:
        return tuple(quality.segments)
    t = log.t
    if log.testbed is not None:
        return segments_of(t, log.testbed.sensors.dt)
    return segments_of(t, float(np.median(np.diff(t)))) if log.n > 1 else ((0, log.n),)


def with_breaks(t: np.ndarray, y: np.ndarray, segments) -> tuple[np.ndarray, np.ndarray]:
    """``t`` and ``y`` with a NaN between segments, so a plotted line breaks at each gap."""
    ts, ys = [], []
    for k, (a, b) in enumerate(segments):
        if k:
            ts.append([np.nan])
            ys.append([np.nan])
        ts.append(t[a:b])
        ys.append(y[a:b])
    return np.concatenate(ts), np.concatenate(ys)


def local_residual(
    y: np.ndarray, segments, t: np.ndarray | None = None, window: int = TREND_WINDOW
) -> np.ndarray:
    """``y`` minus its local trend, within each segment.

    The local trend at a sample is a robust straight line through the ``window``
    samples centred on it (fewer at a segment's ends): slope the median of the
    sample-to-sample slopes, level the median of ``y`` moved along that slope to the
    sample's time. A motion that is straight over the window (a spin, a slow swing)
    leaves the noise only; a glitch of up to ``(window - 1) / 2`` samples moves neither
    median and stands out whole. NaN in segments shorter than 3 samples.
    """
    y = np.asarray(y, dtype=float)
    t = np.arange(len(y), dtype=float) if t is None else np.asarray(t, dtype=float)
    out = np.full(len(y), np.nan)
    half = window // 2
    pad = np.full(half, np.nan)
    for a, b in segments:
        if b - a < 3:
            continue
        ys = np.lib.stride_tricks.sliding_window_view(np.concatenate([pad, y[a:b], pad]), window)
        ts = np.lib.stride_tricks.sliding_window_view(np.concatenate([pad, t[a:b], pad]), window)
        slope = np.nanmedian(np.diff(ys, axis=1) / np.diff(ts, axis=1), axis=1)
        centre = t[a:b]
        level = np.nanmedian(ys - slope[:, None] * (ts - centre[:, None]), axis=1)
        out[a:b] = y[a:b] - level
    return out


def _break_at_wraps(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A NaN where a wrapped angle (deg) jumps by more than 180 deg: no line across it."""
    jumps = np.flatnonzero(np.abs(np.diff(y)) > 180.0) + 1
    return np.insert(t, jumps, np.nan), np.insert(y, jumps, np.nan)


def _unwrap(y: np.ndarray, segments) -> np.ndarray:
    out = np.array(y, dtype=float)
    for a, b in segments:
        out[a:b] = np.unwrap(out[a:b])
    return out


def _yaw_rate(t: np.ndarray, yaw: np.ndarray, segments) -> np.ndarray:
    out = np.full(len(t), np.nan)
    for a, b in segments:
        if b - a >= 2:
            out[a:b] = np.gradient(yaw[a:b], t[a:b])
    return out


def _wheel_series(log: Log) -> list:
    """Panels of the reaction wheels: measured speeds (rpm) and commands (mN m or rpm)."""
    out = []
    ws = [c for c in WHEEL_SPEED_COLUMNS if c in log.data.columns]
    if ws:
        out.append(("wheel speeds", "wheel speed (rpm)",
                    [(c, log.column(c) * _RPM, None) for c in ws]))  # fmt: skip
    wc = [c for c in WHEEL_COMMAND_COLUMNS if c in log.data.columns]
    if wc:
        wheels = log.testbed.wheels if log.testbed is not None else None
        if wheels is None:
            label, factor = "command (N m or rad/s)", 1.0
        elif wheels.command == "speed":
            label, factor = "speed command (rpm)", _RPM
        else:
            label, factor = "torque command (mN m)", 1e3
        out.append(("wheel commands", label, [(c, log.column(c) * factor, None) for c in wc]))
    return out


def log_figure(log: Log, quality: LogQuality | None = None, *, title: str | None = None):
    """A figure of every logged channel against time.

    Parameters
    ----------
    log : Log
    quality : LogQuality or None
        If given, gaps between segments are shaded grey and outlier samples are
        circled in red on every channel they concern. Without it, segments are found
        from the testbed's rate (or the median interval).
    title : str or None
        Figure title (default: the log's source).

    Returns
    -------
    matplotlib.figure.Figure
        One panel per channel group present (attitude, rates, sliders, ...), time
        in s on the shared x axis, each y axis labelled in words with its unit; lines
        break at gaps. A ``yaw`` column adds two panels: the yaw rate from the logged
        angle (deg/s) and the residual from the local trend (deg, :func:`local_residual`);
        yaw itself is shown wrapped to (-180, 180] deg.
    """
    panels = [p for p in _PANELS if log.has(*p[1])]
    if log.testbed is not None and not log.testbed.sensors.gyro:
        panels = [p for p in panels if p[0] != "angular rate"]
    t = log.t
    segments = _segments(log, quality)
    series: list[tuple[str, str, list[tuple[str, np.ndarray, np.ndarray]]]] = []
    for name, cols, label, factor in panels:
        if name == "yaw":
            yaw = _unwrap(log.column("yaw"), segments)
            # (-180, 180]: a slew that ends at 180 deg stays at +180
            wrapped = (np.pi - np.mod(np.pi - yaw, 2 * np.pi)) * factor
            series.append(("yaw, wrapped to +-180 deg", "yaw angle (deg)",
                           [("yaw", wrapped, log.column("yaw") * factor)]))  # fmt: skip
            series.append(("yaw rate from the logged yaw", "yaw rate (deg/s)",
                           [("d yaw / dt", _yaw_rate(t, yaw, segments) * _DEG, None)]))  # fmt: skip
            series.append((
                f"yaw minus its local trend (a robust line through {TREND_WINDOW} samples): "
                "a glitch stands out here",
                "yaw residual (deg)",
                [("yaw residual", local_residual(yaw, segments, t) * factor, None)],
            ))  # fmt: skip
            continue
        series.append((name, label, [(c, log.column(c) * factor, None) for c in cols]))
    series += _wheel_series(log)
    # an ideal log's residual from its trend is roundoff (1e-14 deg): a panel of it would
    # draw a "glitch" that is not in the data
    series = [
        sr
        for sr in series
        if not (sr[1] == "yaw residual (deg)" and _roundoff(sr[2][0][1], scale=180.0))
    ]
    n_panels = max(len(series), 1)
    fig, axes = plt.subplots(
        n_panels, 1, sharex=True, figsize=(9, 2.3 * n_panels + 0.6), layout="constrained"
    )
    axes = np.atleast_1d(axes)
    outlier_cols: dict[int, tuple[str, ...]] = {}
    if quality is not None:
        outlier_cols = {o.row: o.columns for o in quality.outliers}
    # a one-sample segment (a stretch sampled slower than the testbed's rate) has no line:
    # its samples are drawn as dots, so every row of the log is on the figure
    lone = np.array([a for a, b in segments if b - a == 1], dtype=int)
    steps = [] if quality is None else [d.row for d in quality.discontinuities]
    for ax, (name, label, lines) in zip(axes, series, strict=False):
        for c, y, _raw in lines:
            tb, yb = with_breaks(t, y, segments)
            if name.startswith("yaw, wrapped"):
                tb, yb = _break_at_wraps(tb, yb)
            (line,) = ax.plot(tb, yb, lw=0.8, label=c)
            if lone.size:
                ax.plot(t[lone], y[lone], ".", ms=3, color=line.get_color())
        for row in steps:  # a step breaks the segment: marked where the new one starts
            ax.axvline(t[row], color="red", ls="--", lw=0.8, zorder=0)
        for (_, b), (a2, _) in zip(segments[:-1], segments[1:], strict=True):
            ax.axvspan(t[b - 1], t[a2], color="0.85", zorder=0)
        for row, ocols in outlier_cols.items():
            for c, y, _raw in lines:
                if c in ocols:
                    ax.plot(t[row], y[row], "o", mfc="none", mec="red", ms=8)
        ax.set_ylabel(label)
        _plain_axis(ax, [y for _c, y, _raw in lines])
        ax.set_title(name, fontsize=10, loc="left")
        if len(lines) > 1:
            ax.legend(loc="upper right", fontsize=8, ncol=len(lines))
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    note = f" — {len(segments)} segment(s), gaps shown as breaks"
    if quality is not None:
        note += f", {len(quality.outlier_rows)} outlier row(s) (red circles)"
        if steps:
            note += f", {len(steps)} step(s) (red dashes)"
    fig.suptitle((title or source_name(log)) + note, fontsize=10)
    fig.align_ylabels(axes)
    return fig


def source_name(log: Log) -> str:
    """What a log is, for a title: its file, or "TESTBED, simulated" (not "<simulation>")."""
    src = str(log.source)
    if src.startswith("<") and src.endswith(">"):
        tb = log.testbed.name if log.testbed is not None else "log"
        return f"{tb}, {'simulated' if 'simul' in src else 'in memory'}"
    return src


def _roundoff(y: np.ndarray, scale: float) -> bool:
    """Whether every finite value of ``y`` is roundoff next to ``scale`` (or there is none)."""
    y = np.asarray(y, dtype=float)
    y = y[np.isfinite(y)]
    return y.size == 0 or float(np.max(np.abs(y))) <= 1e-9 * scale


def _plain_axis(ax, ys) -> None:
    """Tick labels a person reads: no offset ("1e-10+5.7e1"), and a channel constant to
    roundoff drawn as a flat line in a window of its own size, not magnified noise."""
    ax.ticklabel_format(axis="y", useOffset=False, style="plain")
    values = np.concatenate([np.asarray(y, dtype=float).ravel() for y in ys]) if ys else []
    values = values[np.isfinite(values)] if len(values) else values
    if len(values) == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    size = max(abs(lo), abs(hi))
    if hi - lo <= 1e-9 * max(size, 1e-300) or (size == 0.0):
        mid = 0.5 * (lo + hi)
        half = 0.1 * abs(mid) if mid != 0 else 1.0
        ax.set_ylim(mid - half, mid + half)


def log_report_html(log: Log, quality: LogQuality | None = None) -> str:
    """A self-contained HTML page with :func:`log_figure` and the outlier table."""
    report = Report(f"Log {log.source}")
    report.raw(figure_html(log_figure(log, quality), "Logged channels against time."))
    if quality is not None:
        report.paragraph(
            f"{log.n} rows in {quality.n_segments} segment(s). Jitter {quality.jitter:.3f}."
        )
        for what, text in quality.findings():  # the words of ``log import``
            report.paragraph(f"{what.capitalize()}: {text}")
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
