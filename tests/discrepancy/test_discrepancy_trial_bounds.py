"""A candidate pinned at either end of its physical range is never named."""

from __future__ import annotations

import numpy as np
import pytest
from judging import judged

from airbearing.analysis.discrepancy.candidates import Candidate


def _judged(value: float, std: float = 0.06):
    cand = Candidate(name="sensor_lag", params=("tau_lag",), tie=np.ones((1, 1)),
                     lower=(0.0,), upper=(1.0,), lag=True)  # fmt: skip
    return judged(cand, value, std)


@pytest.mark.parametrize("value, words", [(0.0, "bound 0"), (1.0, "largest physical value 1")])
def test_pinned_at_either_end_is_at_its_bound(value, words):
    r = _judged(value)
    assert r.status == "at its physical bound" and words in r.reason, r.reason
    assert not r.nameable


def test_inside_the_range_is_judged_on_its_merits():
    r = _judged(0.3)
    assert r.status != "at its physical bound" and r.nameable, (r.status, r.reason)
