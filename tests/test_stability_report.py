"""The stability report: HTML rendered in headless Chromium, JSON, and the CLI."""

import json

import pytest
from html_check import bad_text, check_layout, page_text, render, require_chromium

import airbearing.cli as cli
import airbearing.cli.gains  # noqa: F401  (registers the commands)
from airbearing.io.testbed import load_testbed
from airbearing.reporting.html import write_json
from airbearing.reporting.stability import stability_report


@pytest.fixture(scope="module")
def attitude_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    rep, data = stability_report(load_testbed("cmg-yaw"), "attitude")
    rep.write(d / "report.html")
    write_json(d / "margins.json", data)
    return d, data


@pytest.fixture(scope="module")
def balancing_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("report-balancing")
    rep, _ = stability_report(load_testbed("seed000-tabletop"), "balancing")
    rep.write(d / "report.html")
    return d


def test_json_has_every_loop_and_the_required_keys(attitude_report):
    d, _ = attitude_report
    data = json.loads((d / "margins.json").read_text())
    assert set(data["loops"]) == {"dd1", "dd2", "dd3", "dd4", "yaw"}
    for m in data["loops"].values():
        for key in (
            "gain_margin_db",
            "phase_margin_deg",
            "delay_margin_s",
            "disk_margin",
            "closed_loop_poles",
            "stable",
        ):
            assert key in m
        assert m["stable"] is True
    # each gimbal alone never reaches |L| = 1: an infinite phase margin is written as null
    assert data["loops"]["dd1"]["phase_margin_deg"] is None
    # seed 001 gains: the yaw loop's discrete margins (linear analysis of Table 6 gains)
    assert data["loops"]["yaw"]["phase_margin_deg"] > 45


def test_report_tables_have_no_nan_or_inf_text(attitude_report, balancing_report):
    for d in (attitude_report[0], balancing_report):
        assert bad_text((d / "report.html").read_text()) == [], d
    # the one-sample computation delay puts closed-loop poles at z = 0, where log(z)/dt
    # (w_n, damping) does not exist: named, not printed as inf/nan
    assert "delay (z = 0)" in page_text((balancing_report / "report.html").read_text())


@pytest.mark.parametrize("width", [1200, 700], ids=["wide-window", "narrow-window"])
def test_report_renders_in_headless_chromium(attitude_report, balancing_report, tmp_path, width):
    require_chromium()
    for d in (attitude_report[0], balancing_report):
        png = tmp_path / f"{d.name}-{width}.png"
        dom = render(d / "report.html", tmp_path, width, screenshot=png)
        assert dom.count("<figure>") >= 4  # Bode, Nyquist, responses, pole map
        assert dom.count("data:image/svg+xml;base64,") >= 4  # embedded, no network
        assert dom.count("<table>") >= 4  # gains, margins (discrete, continuous), spec, poles
        assert "Traceback" not in dom and "http://" not in dom and "https://" not in dom
        check_layout(dom, f"{d.name} at {width} px")
        assert bad_text(dom) == [], "nan/inf text in the rendered page"
        assert png.stat().st_size > 10_000


def _main(args):
    try:
        cli.main(args)
    except SystemExit as e:
        return e.code
    return 0


def test_cli_gains_then_report(tmp_path, capsys):
    g = tmp_path / "gains.json"
    assert _main(["gains", "cmg-yaw", "--loop", "attitude", "--json", str(g)]) == 0
    data = json.loads(g.read_text())
    assert data["loop"] == "attitude" and data["met"] is True
    html, m = tmp_path / "r.html", tmp_path / "m.json"
    assert (
        _main(
            [
                "report",
                "cmg-yaw",
                "--loop",
                "attitude",
                "--gains",
                str(g),
                "-o",
                str(html),
                "--json",
                str(m),
            ]
        )
        == 0
    )
    assert html.exists() and json.loads(m.read_text())["gains"] == data["gains"]
    # gains of the wrong loop: a clear error, exit 2, no output written
    bad = tmp_path / "bad.html"
    assert (
        _main(["report", "platform-3dof", "--loop", "balancing", "--gains", str(g), "-o", str(bad)])
        == 2
    )
    # it names what the gains are for, what was asked, and the option that fixes it
    err = capsys.readouterr().err
    assert "the report is of the balancing loop; pass --loop attitude" in err
    assert not bad.exists()
    assert _main(["gains", "cmg-yaw", "--loop", "roll"]) == 2
    assert _main(["gains", "cmg-yaw", "--phase-margin-deg", "-5"]) == 2
