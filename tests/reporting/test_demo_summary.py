"""The demo report opens with a summary a lab reads in a minute, and a linked contents."""

from __future__ import annotations

import re

from airbearing.reporting import demo


def _passing(report, *, quick=False):
    report.heading("A passing section")
    report.heading("Its detail", level=3)
    report.table([{"check": "margin", "met": True}, {"check": "overshoot", "met": True}])


def _failing(report, *, quick=False):
    report.heading("A failing section")
    report.table([{"check": "slider travel", "met": False}, {"check": "margin", "met": True}])


def _render(tmp_path, monkeypatch, sections, expected):
    monkeypatch.setattr(demo, "SECTIONS", sections)
    monkeypatch.setattr(demo, "EXPECTED", expected)
    monkeypatch.setattr(demo, "SHOWS", {t: f"what {t} shows" for t, _ in sections})
    return demo.run_demo(tmp_path, quick=True).read_text()


def test_summary_counts_checks_and_says_whether_a_failure_is_expected(tmp_path, monkeypatch):
    html = _render(
        tmp_path, monkeypatch, [("Good", _passing), ("Bad", _failing)], {"Bad": "on purpose"}
    )
    summary = html[html.index("<h2>Summary</h2>") : html.index("<h2>Contents</h2>")]
    rows = re.findall(r"<tr>(.*?)</tr>", summary, re.S)[1:]
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r, re.S) for r in rows]
    assert [c[2:4] for c in cells] == [["2", "0"], ["1", "1"]]
    assert "what Good shows" in cells[0][1] and cells[0][4] == "all checks pass"
    assert cells[1][4] == "1 not met, expected: on purpose"
    # the summary comes first, before any section
    assert html.index("<h2>Summary</h2>") < html.index("A passing section")


def test_an_unexpected_failure_is_flagged(tmp_path, monkeypatch):
    html = _render(tmp_path, monkeypatch, [("Bad", _failing)], {})
    assert "NOT expected" in html


def test_contents_link_every_heading(tmp_path, monkeypatch):
    html = _render(tmp_path, monkeypatch, [("Good", _passing), ("Bad", _failing)], {})
    contents = html[html.index("<h2>Contents</h2>") :]
    links = re.findall(r'<a href="#([^"]+)">([^<]+)</a>', contents)
    assert [t for _, t in links] == ["A passing section", "Its detail", "A failing section"]
    for anchor, _ in links:
        assert f'id="{anchor}"' in html
