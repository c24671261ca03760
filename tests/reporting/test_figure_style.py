"""Report figures show the data: no offset tick labels, no roundoff panels, no bands."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402

from airbearing.reporting.html import plt  # noqa: E402
from airbearing.reporting.log_plot import log_figure  # noqa: E402
from airbearing.reporting.style import axis_label, chatters, trace  # noqa: E402


def _ideal_spin_log(tmp_path):
    from airbearing.io.log import read_log

    # an ideal log: yaw exactly linear (1 deg/s) around 57.3 deg, rate constant
    t = np.arange(200) * 0.05
    yaw = 1.0 + np.deg2rad(1.0) * t
    path = tmp_path / "ideal.csv"
    w = np.deg2rad(1.0)
    rows = "\n".join(
        f"{a:.3f},{y:.17g},{w:.17g},0,0,0,0,0,0,0,0" for a, y in zip(t, yaw, strict=True)
    )
    path.write_text("t,yaw,wz,d1,d2,d3,d4,dd1,dd2,dd3,dd4\n" + rows + "\n")
    return read_log(path, "cmg-yaw")


def test_an_ideal_log_has_no_offset_labels_and_no_roundoff_panel(tmp_path):
    fig = log_figure(_ideal_spin_log(tmp_path))
    fig.canvas.draw()
    titles = [ax.get_title(loc="left") for ax in fig.axes]
    assert not any("local trend" in t for t in titles), titles  # the residual is roundoff
    for ax in fig.axes:
        assert ax.yaxis.get_offset_text().get_text() == "", ax.get_ylabel()
    plt.close(fig)


def test_a_chattering_trace_is_drawn_as_samples_not_a_band():
    t = np.linspace(0, 10, 2000)
    chatter = 0.05 + 0.04 * (-1.0) ** np.arange(t.size)
    smooth = np.sin(t)
    assert chatters(chatter) and not chatters(smooth)
    fig, ax = plt.subplots()
    a = trace(ax, t, chatter, "mp", 0)
    b = trace(ax, t, smooth, "gsr", 1)
    assert a.get_linestyle() == "None" and len(a.get_xdata()) < t.size / 10
    assert b.get_linestyle() == "-" and len(b.get_xdata()) == t.size
    plt.close(fig)


def test_axis_labels_are_words_with_units():
    assert axis_label("peak_rate_deg_s") == "peak rate (deg/s)"
    assert axis_label("final_error_deg") == "final error (deg)"
