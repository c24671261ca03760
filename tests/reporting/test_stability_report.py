"""The stability report: HTML rendered in headless Chromium, JSON, and the CLI.

Two reports serve every test here, each made once per module by the CLI in-process: the
README's ``gains`` then ``report`` commands on ``cmg-yaw``'s attitude loop, exactly as the
README writes them (the README test leaves them to this file), and ``gains`` then
``report --gains`` on seed 004's balancing loop.
"""

import json
import os

import numpy as np
import pytest
from conftest import README_GAINS_ARGS, README_REPORT_ARGS
from html_check import bad_text, check_layout, page_text, render, require_chromium

import airbearing.cli as cli
import airbearing.cli.gains  # noqa: F401  (registers the commands)
from airbearing.io.testbed import load_testbed


def _main(args):
    try:
        cli.main(args)
    except SystemExit as e:
        return e.code
    return 0


def _in(folder, commands):
    """Run ``commands`` (argument lists) in-process in ``folder``: their exit statuses."""
    here = os.getcwd()
    os.chdir(folder)
    try:
        return [_main(args) for args in commands]
    finally:
        os.chdir(here)


@pytest.fixture(scope="module")
def attitude_report(tmp_path_factory, library_patches):
    """The README's ``gains`` and ``report`` commands on cmg-yaw: (folder, exit statuses).

    Their tuning and analysis are the library calls of the same arguments other tests make
    (tests/conftest.py ``library_patches``: once per test run); the commands' parsing,
    files and rendering are theirs. The balancing pair below runs its own end to end."""
    d = tmp_path_factory.mktemp("report")
    with pytest.MonkeyPatch.context() as mp:
        library_patches(mp)
        return d, _in(d, [README_GAINS_ARGS, README_REPORT_ARGS])


@pytest.fixture(scope="module")
def balancing_report(tmp_path_factory):
    """``gains`` then ``report --gains`` on seed 004's balancing loop (mechanical split), on
    the nominal inertia (the default box's three vertical offsets, not nine corners: a third
    of the work; the report takes the specification from the gains file, and the default
    box's tuning is test_tuning.py's test_balancing_loop_of_seed004_meets_its_spec)."""
    d = tmp_path_factory.mktemp("report-balancing")
    name, split = "seed004-platform", "mechanical"
    codes = _in(d, [["gains", name, "--loop", "balancing", "--split", split,
                     "--inertia-uncertainty", "0", "--json", "g.json"],
                    ["report", name, "--loop", "balancing", "--gains", "g.json",
                     "-o", "report.html", "--json", "m.json"]])  # fmt: skip
    assert codes == [0, 0]
    return d


@pytest.mark.slow
def test_json_has_every_loop_and_the_required_keys(attitude_report):
    d, codes = attitude_report
    assert codes == [0, 0]
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
    # the tuned gains: the yaw loop's discrete margin meets the specification's 45 deg
    # (the seed-001 gains' margins are checked in the demo's linear stability section)
    assert data["loops"]["yaw"]["phase_margin_deg"] > 45


@pytest.mark.slow
def test_report_tables_have_no_nan_or_inf_text(attitude_report, balancing_report):
    for d in (attitude_report[0], balancing_report):
        assert bad_text((d / "report.html").read_text()) == [], d


def test_poles_at_the_origin_and_at_one_are_named_not_nan(tmp_path):
    """The one-sample computation delay can put closed-loop poles at z = 0 (seed000's mixed
    balancing loop with the seed gains has them), where log(z)/dt (w_n, damping) does not
    exist, and an integral action leaves one at z = 1: named in the pole table, not
    printed as inf/nan (the table a report writes, on those poles)."""
    from airbearing.reporting.html import Report
    from airbearing.reporting.stability import _pole_map

    rep = Report("poles")
    _pole_map(rep, np.array([0j, 0j, 1 + 0j, 0.9 + 0.1j, 0.9 - 0.1j]), 0.05)
    rep.write(tmp_path / "poles.html")
    html = (tmp_path / "poles.html").read_text()
    assert bad_text(html) == []
    text = page_text(html)
    assert text.count("delay (z = 0)") == 2 and "integrator" in text


@pytest.mark.parametrize("width", [1200, 700], ids=["wide-window", "narrow-window"])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
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


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_cli_gains_then_report(attitude_report, tmp_path, capsys):
    d, codes = attitude_report
    assert codes == [0, 0]
    data = json.loads((d / "gains.json").read_text())
    assert data["loop"] == "attitude" and data["met"] is True
    report = json.loads((d / "margins.json").read_text())
    assert (d / "report.html").exists() and report["gains"] == data["gains"]
    # the tuner checks what the report checks, all channels at once included, and the
    # two agree on every check and on the verdict
    assert report["met"] is data["met"] is True
    assert [(c["name"], c["met"]) for c in report["checks"]] == [
        (c["name"], c["met"]) for c in data["checks"]
    ]
    assert "phase margin, all channels at once (deg)" in {c["name"] for c in data["checks"]}
    # gains of the wrong loop: a clear error, exit 2, no output written
    bad = tmp_path / "bad.html"
    g = str(d / "gains.json")
    assert (
        _main(["report", "platform-3dof", "--loop", "balancing", "--gains", g, "-o", str(bad)]) == 2
    )
    # it names what the gains are for, what was asked, and the option that fixes it
    err = capsys.readouterr().err
    assert "the report is of the balancing loop; pass --loop attitude" in err
    assert not bad.exists()
    assert _main(["gains", "cmg-yaw", "--loop", "roll"]) == 2
    assert _main(["gains", "cmg-yaw", "--phase-margin-deg", "-5"]) == 2


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_gains_and_report_agree_on_a_balancing_loop(balancing_report):
    """``gains`` then ``report --gains`` on seed 004's platform: the same checks, values
    and verdict (seed000-tabletop's mixed loop: test_tuning's unreachable-trim test)."""
    d = balancing_report
    tuned, report = json.loads((d / "g.json").read_text()), json.loads((d / "m.json").read_text())
    assert report["met"] is tuned["met"]
    for a, b in zip(tuned["checks"], report["checks"], strict=True):
        assert (a["name"], a["met"]) == (b["name"], b["met"])
        if a["value"] is not None:
            assert a["value"] == pytest.approx(b["value"], rel=1e-9)
    assert report["met"] is True


def test_margins_of_an_unstable_loop_are_not_marked_ok():
    """The per-channel table of an unstable loop: its margins are numbers, not verdicts
    (as the tuner's checks say: n/a), and its legend says why."""
    from airbearing.design.linearise import scaled_params
    from airbearing.design.loops import make_loop
    from airbearing.design.margins import analyse_loop
    from airbearing.design.tuning import Spec
    from airbearing.reporting.stability import _margin_legend, _margin_rows

    # K_p = 0 cannot hold the CM 0.5 mm above the bearing (test_tuning's UNSTABLE_BALANCING)
    lp = make_loop(load_testbed("seed004-platform"), "balancing", split="mechanical",
                   gains={"K_p": 0.0, "K_d": 0.008969, "K_dK_i": 3.197e-05})  # fmt: skip
    lp = lp.with_params(scaled_params(lp.model, lp.p, r_z=0.5e-3))
    a = analyse_loop(lp, multiloop=False)
    assert not a.stable
    rows = _margin_rows(a, Spec())
    assert rows and all(r[k] == "n/a" for r in rows for k in ("GM ok", "PM ok", "Ms ok"))
    assert "n/a: the closed loop is unstable" in _margin_legend(a)
    stable = analyse_loop(make_loop(load_testbed("cmg-yaw"), "attitude"), multiloop=False)
    assert all(isinstance(r["PM ok"], bool) for r in _margin_rows(stable, Spec()))
    assert "n/a" not in _margin_legend(stable)


def test_per_corner_columns_have_their_units():
    """The per-corner table's headers: every key's unit in words (was 'overshoot pct')."""
    from airbearing.reporting.html import pretty_key
    from airbearing.reporting.stability import _CORNER_COLUMNS

    assert pretty_key("overshoot_pct") == "overshoot (%)"
    assert pretty_key("slew_overshoot_pct") == "slew overshoot (%)"
    assert pretty_key("settling_time_s") == "settling time (s)"
    assert _CORNER_COLUMNS["multiloop_disk_margin"] == "disk margin, all channels at once"
