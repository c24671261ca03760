"""Every demo section checks itself against the truth it simulated, as pass/FAIL cells the
summary counts; a failure a section expects says why, in its table and in the summary."""

from __future__ import annotations

import re

from airbearing.reporting import demo
from airbearing.reporting.checks import check, checks_table, within


def test_within_and_a_missing_answer():
    assert within(51.07, 51.38, rel=0.02) and not within(50.0, 51.38, rel=0.02)
    assert within(-63.09, -63.75, abs_=1.5) and not within(-60.0, -63.75, abs_=1.5)
    assert not within(None, 1.0, abs_=10.0) and not within(float("nan"), 1.0, abs_=10.0)


def _expected_failure(report, *, quick=False):
    report.heading("A section that knows a check fails")
    checks_table(
        report,
        [
            check("peak rate (deg/s)", 51.38, 51.07, "within 2 %", True),
            check("final error (deg)", 0.0, 2.9, "< 0.5", False, expected="the run is cut short"),
        ],
    )


def _unexpected_failure(report, *, quick=False):
    report.heading("A section that fails")
    checks_table(report, [check("J_zz (g m^2)", 36.4, 30.0, "within 2 %", False)])


def _render(tmp_path, monkeypatch, sections):
    monkeypatch.setattr(demo, "SECTIONS", sections)
    monkeypatch.setattr(demo, "EXPECTED", {})
    return demo.run_demo(tmp_path, quick=True).read_text()


def _summary_cells(html: str) -> list[list[str]]:
    summary = html[html.index("<h2>Summary</h2>") : html.index("<h2>Contents</h2>")]
    rows = re.findall(r"<tr>(.*?)</tr>", summary, re.S)[1:]
    return [re.findall(r"<td[^>]*>(.*?)</td>", r, re.S) for r in rows]


def test_an_expected_failure_says_why_and_is_counted_apart(tmp_path, monkeypatch):
    html = _render(tmp_path, monkeypatch, [("Known", _expected_failure)])
    assert 'class="fail-expected">FAIL, expected<' in html
    assert "the run is cut short" in html  # its table says why
    (cells,) = _summary_cells(html)
    assert cells[2:4] == ["1", "1"]  # one passed, one not met
    assert cells[4] == "1 not met, expected: the section&#x27;s table says why"
    assert "NOT expected" not in html


def test_an_unexpected_failure_is_flagged_beside_expected_ones(tmp_path, monkeypatch):
    sections = [("Known", _expected_failure), ("Broken", _unexpected_failure)]
    html = _render(tmp_path, monkeypatch, sections)
    known, broken = _summary_cells(html)
    assert "NOT expected" not in known[4]
    assert broken[3] == "1" and "NOT expected" in broken[4]


def test_every_section_has_checks():
    # each section module builds a checks table (a pass/FAIL cell per check)
    import inspect

    for title, section in demo.SECTIONS:
        if title == "Foundation":
            source = inspect.getsource(demo)
        else:
            module = section.__name__.rsplit(".", 1)[0]
            source = inspect.getsource(__import__(module, fromlist=["_"]))
        assert "checks_table(" in source or '"met"' in source, title
