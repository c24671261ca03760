"""Checks of a demo section against the truth it simulated, as pass/FAIL table cells.

Every section of the demo simulates with a truth it knows (the seed papers' values, the
inertia or effect it hid in the simulated rig). :func:`check` makes one table row: what is
checked (with its unit), the truth, what the tools found, the rule, and whether it is met;
:func:`checks_table` adds the rows to the report, a pass/FAIL cell each, which the demo's
summary counts (:mod:`airbearing.reporting.demo`). A check that fails on purpose says why
in ``expected`` (its cell reads "FAIL, expected" and the summary counts it apart).
"""

from __future__ import annotations

import math

from airbearing.reporting.html import EXPECTED_KEY, Report

__all__ = ["check", "checks_table", "within"]

_COLUMNS = ["check", "truth", "found", "std", "rule", "met"]


def within(found, truth, *, rel: float | None = None, abs_: float | None = None) -> bool:
    """``|found - truth| <= rel * |truth| + abs_`` (False when ``found`` is missing or not
    finite)."""
    if found is None or not math.isfinite(float(found)):
        return False
    tol = (rel or 0.0) * abs(float(truth)) + (abs_ or 0.0)
    return abs(float(found) - float(truth)) <= tol


def check(
    what: str,
    truth,
    found,
    rule: str,
    met: bool,
    *,
    std: float | None = None,
    expected: str = "",
) -> dict:
    """One check as a table row.

    Parameters
    ----------
    what : str
        What is checked, with its unit in parentheses.
    truth, found
        The value the section simulated (or the paper's), and the tools' answer (numbers,
        or words when the check is about a name).
    rule : str
        The rule in words ("within 3 std", "<= 1.5").
    met : bool
        Whether the rule holds.
    std : float, optional
        Standard error of ``found``, when the rule uses it.
    expected : str, optional
        Why a failure of this check is expected (the summary says so); "" when it is not.
    """
    row = {
        "check": what,
        "truth": truth,
        "found": found,
        "std": std,
        "rule": rule,
        "met": bool(met),
    }
    if expected and not met:
        row[EXPECTED_KEY] = expected
    return row


def checks_table(report: Report, rows: list[dict], *, title: str | None = None) -> None:
    """The section's checks as one table (a "failure expected because" column when one
    failure is expected)."""
    if title:
        report.paragraph(title)
    cols = _COLUMNS + ([EXPECTED_KEY] if any(r.get(EXPECTED_KEY) for r in rows) else [])
    report.table(rows, cols, legend="no standard error: a count, a ratio or a paper's value")
