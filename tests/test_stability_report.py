"""The stability report: HTML rendered in headless Chromium, JSON, and the CLI."""

import html
import json
import re
import shutil
import subprocess

import pytest

import airbearing.cli as cli
import airbearing.cli.gains  # noqa: F401  (registers the commands)
from airbearing.io.testbed import load_testbed
from airbearing.reporting.html import write_json
from airbearing.reporting.stability import stability_report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


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


#: Runs in the page once it has loaded: does the page scroll sideways (a table or figure
#: wider than the window), and how many tables sit outside a scrolling wrapper.
_PROBE = """<script>window.addEventListener('load', function () {
  var de = document.documentElement;
  document.body.setAttribute('data-overflow', String(de.scrollWidth > de.clientWidth + 1));
  var loose = 0;
  document.querySelectorAll('table').forEach(function (t) { if (!t.closest('.scroll')) loose++; });
  document.body.setAttribute('data-loose-tables', String(loose));
});</script>"""

_BAD_TEXT = re.compile(r"(?i)\b(?:nan|-?inf|infinity)\b")


def _page_text(dom: str) -> str:
    dom = re.sub(r"(?s)<(script|style)\b.*?</\1>", " ", dom)
    return html.unescape(re.sub(r"<[^>]+>", " ", dom))


def test_report_tables_have_no_nan_or_inf_text(attitude_report, balancing_report):
    for d in (attitude_report[0], balancing_report):
        text = _page_text((d / "report.html").read_text())
        assert _BAD_TEXT.findall(text) == [], d
    # the one-sample computation delay puts closed-loop poles at z = 0, where log(z)/dt
    # (w_n, damping) does not exist: named, not printed as inf/nan
    assert "delay (z = 0)" in _page_text((balancing_report / "report.html").read_text())


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (CI's .ci/run installs it)")
@pytest.mark.parametrize("width", [1200, 700], ids=["wide-window", "narrow-window"])
def test_report_renders_in_headless_chromium(attitude_report, balancing_report, tmp_path, width):
    for d in (attitude_report[0], balancing_report):
        page = tmp_path / f"{d.name}.html"
        page.write_text((d / "report.html").read_text().replace("</body>", _PROBE + "</body>"))
        png = tmp_path / f"{d.name}.png"
        cmd = [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={tmp_path / 'profile'}",
            f"--window-size={width},3000",
            "--virtual-time-budget=5000",
            f"--screenshot={png}",
            "--dump-dom",
            page.as_uri(),
        ]
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        dom = out.stdout
        assert dom.count("<figure>") >= 4  # Bode, Nyquist, responses, pole map
        assert dom.count("data:image/svg+xml;base64,") >= 4  # embedded, no network
        assert dom.count("<table>") >= 4  # gains, margins (discrete, continuous), spec, poles
        assert "Traceback" not in dom and "http://" not in dom and "https://" not in dom
        assert 'data-overflow="false"' in dom, f"{d.name}: the page scrolls sideways at {width} px"
        assert 'data-loose-tables="0"' in dom, "a table outside its scrolling wrapper"
        assert _BAD_TEXT.findall(_page_text(dom)) == [], "nan/inf text in the rendered page"
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
    assert "gains of the attitude loop" in capsys.readouterr().err
    assert not bad.exists()
    assert _main(["gains", "cmg-yaw", "--loop", "roll"]) == 2
    assert _main(["gains", "cmg-yaw", "--phase-margin-deg", "-5"]) == 2
