"""A candidate pinned at either end of its physical range is never named."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from airbearing.analysis.discrepancy.candidates import Candidate
from airbearing.analysis.discrepancy.trial import judge


def _judged(value: float, std: float = 0.06):
    cand = Candidate(name="sensor_lag", params=("tau_lag",), tie=np.ones((1, 1)),
                     lower=(0.0,), upper=(1.0,), lag=True)  # fmt: skip
    fit = SimpleNamespace(
        n_res=1000, rss=1.0, theta=np.array([value]), n_free=1, gap=1e-3,
        not_identifiable=[None], theta_std=np.array([std]), cov=np.array([[std**2]]),
        level="ok", status="ok",
    )  # fmt: skip
    # held out: 1e-3 with the effect, 2e-3 without it (the effect helps there too)
    held = SimpleNamespace(
        rss=np.ones(3), testable=lambda *a: np.ones(3, bool), total=lambda use=None: (1.0, 1e-3)
    )
    before = SimpleNamespace(total=lambda use=None: (4.0, 2e-3))
    return judge(cand, fit, 0, SimpleNamespace(rss=4.0), np.log(1000), 1, held, before, None, "")


@pytest.mark.parametrize("value, words", [(0.0, "bound 0"), (1.0, "largest physical value 1")])
def test_pinned_at_either_end_is_at_its_bound(value, words):
    r = _judged(value)
    assert r.status == "at its physical bound" and words in r.reason, r.reason
    assert not r.nameable


def test_inside_the_range_is_judged_on_its_merits():
    r = _judged(0.3)
    assert r.status != "at its physical bound" and r.nameable, (r.status, r.reason)
