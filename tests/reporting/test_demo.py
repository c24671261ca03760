"""The demo report, from the suite's one demo run (the ``demo_run`` session fixture).

What a reader gets: one self-contained HTML page with every section, no ``nan``/``inf``
text, no sideways overflow in a wide or a narrow window, and progress lines naming each
section on stderr while it runs.
"""

from __future__ import annotations

import pytest
from html_check import bad_text, check_layout, render, require_chromium

pytestmark = [pytest.mark.slow]


def test_demo_runs_and_reports_every_section(demo_run):
    out, proc = demo_run
    assert proc.returncode == 0, proc.stderr[-2000:]
    html = (out / "report.html").read_text()
    assert "Seed 001" in html and "data:image/svg+xml;base64," in html
    # each section's finding (the sections are not run again on their own)
    assert "elliptic internal singularity" in html  # CMG: steering laws at a singularity
    assert "seed-001 inertia story" in html and "inertia_error" in html  # discrepancy
    assert html.count("<img") >= 10  # every section has its figures, embedded
    assert "http://" not in html and "https://" not in html  # self-contained
    assert bad_text(html) == [], "nan/inf text in the demo report"
    # it opens with the summary and the contents, and no failure goes unexplained
    assert html.index("<h2>Summary</h2>") < html.index("<h2>Contents</h2>") < html.index("Seed 001")
    assert "NOT expected" not in html
    assert "platform-3dof" not in html and "&lt;simulation&gt;" not in html


def test_demo_says_which_section_it_is_in(demo_run):
    """stderr is a pipe: plain one-line updates, one per section (no bar, no ANSI codes)."""
    _, proc = demo_run
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("demo: ")]
    assert len(lines) >= 2, proc.stderr
    assert "\x1b[" not in proc.stderr


@pytest.mark.parametrize("width", [1200, 700], ids=["wide-window", "narrow-window"])
def test_demo_report_renders_in_headless_chromium(demo_run, tmp_path, width):
    require_chromium()
    out, proc = demo_run
    assert proc.returncode == 0, proc.stderr[-2000:]
    check_layout(render(out / "report.html", tmp_path, width), f"demo at {width} px")


def test_every_section_checks_itself_against_its_truth(demo_run):
    """Each section's checks are pass/FAIL cells the summary counts: none has none."""
    import re

    out, proc = demo_run
    assert proc.returncode == 0, proc.stderr[-2000:]
    html = (out / "report.html").read_text()
    summary = html[html.index("<h2>Summary</h2>") : html.index("<h2>Contents</h2>")]
    rows = re.findall(r"<tr>(.*?)</tr>", summary, re.S)[1:]
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r, re.S) for r in rows]
    assert len(cells) >= 9
    unchecked = [re.sub("<[^>]+>", "", c[0]) for c in cells if int(c[2]) + int(c[3]) == 0]
    assert unchecked == [], f"sections without a check: {unchecked}"
