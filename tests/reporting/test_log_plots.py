"""Plots that show the artefact: gaps break the line, labels inside, spinning yaw wrapped with
its rate, a glitch visible without its marker; HTML tables with one missing-value symbol and
human column names. Each plot is rendered here."""

from __future__ import annotations

import re
import tomllib

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_RIG_TOML

from airbearing.io.log import Log
from airbearing.io.testbed import testbed_from_dict as _testbed
from airbearing.reporting.html import NONE_TEXT, Report, column_label, table_html
from airbearing.reporting.log_plot import local_residual, log_figure, log_report_html

RIG = _testbed(tomllib.loads(MOCAP_RIG_TOML))  # 10 Hz, yaw only
GLITCH_ROW, GLITCH_DEG = 250, 8.0


def spinning_log() -> Log:
    """A 4 rad/s spin for 60 s (13,750 deg unwrapped), a 20 s gap at row 300, one 8 deg
    glitch at row 250, 1 mrad noise."""
    rng = np.random.default_rng(3)
    n = 600
    t = np.arange(n) * 0.1
    t[300:] += 20.0
    yaw = 0.3 + 4.0 * t + 1e-3 * rng.normal(size=n)
    yaw[GLITCH_ROW] += np.radians(GLITCH_DEG)
    return Log(pd.DataFrame({"t": t, "yaw": yaw}), source="spin.csv", testbed=RIG)


def _axis(fig, words: str):
    return next(ax for ax in fig.axes if words in ax.get_title(loc="left"))


def test_gap_is_a_break_in_every_line():
    fig = log_figure(spinning_log())
    for ax in fig.axes:
        for line in ax.get_lines():
            x = np.asarray(line.get_xdata(), float)
            if len(x) < 10:
                continue
            assert np.isnan(x).any()
            finite_steps = np.diff(x)
            assert np.nanmax(finite_steps) < 1.5 * 0.1 + 1e-9  # no segment across the gap


def test_labels_lie_inside_the_figure():
    fig = log_figure(spinning_log())
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    tight = fig.get_tightbbox(renderer)  # in inches, every artist with its labels
    box = fig.bbox_inches
    assert tight.x0 >= box.x0 - 1e-6 and tight.y0 >= box.y0 - 1e-6
    assert tight.x1 <= box.x1 + 1e-6 and tight.y1 <= box.y1 + 1e-6
    label = fig.axes[-1].xaxis.label
    assert label.get_text() == "time (s)"
    assert fig.bbox.contains(*label.get_window_extent(renderer).p0)


def test_spinning_yaw_is_wrapped_with_its_rate_and_the_glitch_stands_out():
    fig = log_figure(spinning_log())  # no quality given: no outlier marker anywhere
    yaw = np.asarray(_axis(fig, "wrapped").get_lines()[0].get_ydata(), float)
    assert np.nanmax(yaw) <= 180 and np.nanmin(yaw) >= -180
    rate = np.asarray(_axis(fig, "rate").get_lines()[0].get_ydata(), float)
    assert np.nanmedian(rate) == pytest.approx(np.degrees(4.0), rel=1e-3)
    res_ax = _axis(fig, "local trend")
    assert len(res_ax.get_lines()) == 1  # the residual only, no marker
    residual = np.asarray(res_ax.get_lines()[0].get_ydata(), float)
    x = np.asarray(res_ax.get_lines()[0].get_xdata(), float)
    at = int(np.nanargmax(np.abs(residual)))
    assert x[at] == pytest.approx(GLITCH_ROW * 0.1)
    assert abs(residual[at]) == pytest.approx(GLITCH_DEG, rel=0.05)
    others = np.delete(residual, at)
    # the glitch is 8 deg against 1 mrad (0.06 deg) noise: > 30x the largest other residual
    assert abs(residual[at]) > 30 * np.nanmax(np.abs(others))


def test_local_residual_of_a_ramp_is_zero():
    t = np.cumsum(np.full(50, 0.1) + 0.02 * np.sin(np.arange(50)))  # jittered times
    y = 3.0 + 70.0 * t
    assert np.allclose(local_residual(y, ((0, 50),), t), 0.0, atol=1e-9)


@pytest.mark.parametrize("suffix", [".png", ".html"])
def test_log_plot_renders(tmp_path, suffix, capsys):
    log = spinning_log()
    path = tmp_path / "spin.csv"
    log.data.to_csv(path, index=False)
    tb = tmp_path / "rig.toml"
    tb.write_text(MOCAP_RIG_TOML)
    out = tmp_path / f"plot{suffix}"
    assert run(["log", "plot", str(tb), str(path), "-o", str(out)]) == 0
    assert out.stat().st_size > 20_000
    if suffix == ".png":
        assert out.read_bytes()[:4] == b"\x89PNG"
    else:
        assert "data:image/svg+xml;base64," in out.read_text()


def _text(html: str) -> str:
    """What a person reading the page (or a screen reader) gets: tags out, spaces collapsed."""
    return " ".join(re.sub(r"<[^>]+>", " ", html).split())


def test_html_tables_one_missing_symbol_and_human_columns():
    html = table_html(
        [{"final_Hx_h0": "-", "t_peak_s": float("nan"), "peak_rate_deg_s": None, "ok": True},
         {"final_Hx_h0": 0.5, "t_peak_s": 1.25, "peak_rate_deg_s": "—", "ok": False}]
    )  # fmt: skip
    assert "final_Hx_h0" not in html and "final Hx / h0" in html
    assert "t peak (s)" in html and "peak rate (deg/s)" in html
    cells = re.findall(r"<td[^>]*>([^<]*)</td>", html)
    assert cells.count(NONE_TEXT) == 4 and "-" not in cells
    assert column_label("g_perp_rms") == "g perp rms"
    assert column_label("t (s)") == "t (s)"  # already for people
    assert column_label("min_m") == "min m" and column_label("cm_offset_m") == "cm offset (m)"


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_html_sentences_are_separated():
    report = Report("r")
    report.paragraph("yaw in rad")
    report.paragraph("2 outlier row(s)")
    report.figure(log_figure(spinning_log()), "Logged channels")
    text = _text(report.html())
    assert "yaw in rad. 2 outlier row(s)." in text and "Logged channels." in text
    page = _text(log_report_html(spinning_log()))
    assert ".." not in page
