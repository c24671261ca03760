"""Fixtures of the discrepancy search's tests."""

import pytest

from airbearing.analysis.discrepancy import selection


@pytest.fixture
def handed_rounds(monkeypatch):
    """Each round's results as the round hands them over to :func:`.selection._add_best`,
    before it is decided (a list, one tuple per round, filled as the search runs)."""
    handed = []
    add_best = selection._add_best

    def spy(sel, results, prog):
        handed.append(tuple(results))
        return add_best(sel, results, prog)

    monkeypatch.setattr(selection, "_add_best", spy)
    return handed
