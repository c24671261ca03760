"""Shared test helper: what a reader sees of an HTML report (text, overflow in Chromium)."""

from __future__ import annotations

import html
import os
import re
import shutil
import subprocess
from pathlib import Path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def require_chromium() -> str:
    """Chromium's path; without it a test fails when ``CI`` is set (.ci/run installs it),
    and is skipped otherwise (a developer's machine)."""
    import pytest

    if CHROMIUM is not None:
        return CHROMIUM
    if os.environ.get("CI"):
        pytest.fail("chromium is not installed, and CI is set: .ci/run must install it")
    pytest.skip("chromium is not installed (CI's .ci/run installs it; with CI set this fails)")


#: Runs in the page once it has loaded: does the page scroll sideways (a table or figure
#: wider than the window), and how many tables sit outside a scrolling wrapper.
PROBE = """<script>window.addEventListener('load', function () {
  var de = document.documentElement;
  document.body.setAttribute('data-overflow', String(de.scrollWidth > de.clientWidth + 1));
  var loose = 0;
  document.querySelectorAll('table').forEach(function (t) { if (!t.closest('.scroll')) loose++; });
  document.body.setAttribute('data-loose-tables', String(loose));
});</script>"""

BAD_TEXT = re.compile(r"(?i)\b(?:nan|-?inf|infinity)\b")


def page_text(dom: str) -> str:
    """The text of a page (no tags, scripts, styles or embedded images)."""
    dom = re.sub(r"(?s)<(script|style)\b.*?</\1>", " ", dom)
    return html.unescape(re.sub(r"<[^>]+>", " ", dom))


def bad_text(dom: str) -> list[str]:
    """Every 'nan'/'inf' word a reader would see, with some context."""
    text = page_text(dom)
    return [text[max(0, m.start() - 60) : m.end() + 20] for m in BAD_TEXT.finditer(text)]


def render(report: Path, workdir: Path, width: int, screenshot: Path | None = None) -> str:
    """The DOM of ``report`` after Chromium loaded it in a ``width`` px window, probed."""
    page = workdir / f"probe-{report.stem}-{width}.html"
    page.write_text(report.read_text().replace("</body>", PROBE + "</body>"))
    cmd = [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--no-first-run", f"--user-data-dir={workdir / 'chromium-profile'}",
        f"--window-size={width},3000", "--virtual-time-budget=5000",
        *([f"--screenshot={screenshot}"] if screenshot else []),
        "--dump-dom", page.as_uri(),
    ]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def check_layout(dom: str, what: str) -> None:
    """No sideways scrolling of the page, every table in its scrolling wrapper."""
    assert 'data-overflow="false"' in dom, f"{what}: the page scrolls sideways"
    assert 'data-loose-tables="0"' in dom, f"{what}: a table outside its scrolling wrapper"
