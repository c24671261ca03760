"""The discrepancy search tells the progress display how long each step is expected to
take: screens take milliseconds, fits seconds, a first run compiles for minutes.

Mechanism only (no timing): the weights reach the display before the first estimate, a
first run (the first step compiled) weighs the later compiling stages higher than a warm
run, and a screened candidate weighs less than an IPOPT fit.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from rigs import ROTOR

from airbearing.analysis.discrepancy.step_lengths import step_lengths
from airbearing.io.log import Log
from airbearing.progress import TimeLeft


def _cand(name, *, smooth=True, lag=False, per_axis=False):
    """What the weights read of a candidate (:class:`~airbearing.analysis.discrepancy.
    candidates.Candidate`): how it is judged."""
    return SimpleNamespace(name=name, smooth=smooth, lag=lag, per_axis=per_axis)


CANDS = [
    _cand("viscous_friction"),
    _cand("coulomb_friction", smooth=False),  # no derivative at zero rate: an IPOPT fit
    _cand("sensor_lag", smooth=False, lag=True),
    _cand("viscous_friction", per_axis=True),
]


def test_a_first_run_weighs_its_compiling_and_a_screen_weighs_less_than_a_fit():
    cold = step_lengths(CANDS, 2, True, 1, step_s=100.0, compile_s=90.0)  # compiled
    warm = step_lengths(CANDS, 2, True, 1, step_s=10.0, compile_s=0.0)  # from the cache
    # the nominal replay, 2 rounds of 4 candidate slots, the horizon, one validation log
    assert len(cold) == len(warm) == 1 + 2 * 4 + 1 + 1
    assert cold[0] == 100.0 and warm[0] == 10.0  # the first step as timed
    # the same fit time (10 s) in both: the cold run adds compiling to its first round
    # (the lag model's structures), nothing to the second round or the horizon
    assert cold[1] > warm[1] and cold[-2] == pytest.approx(warm[-2])
    assert cold[5:9] == pytest.approx(warm[5:9])
    # a later round starts next to the answer: its fits are shorter than the first's
    assert warm[6] < warm[2]
    # a screened candidate (smooth, no lag: viscous_friction) weighs less than the same
    # candidate fitted by IPOPT (without the screen); the others are fits either way
    unscreened = step_lengths(CANDS, 2, False, 1, step_s=10.0, compile_s=0.0)
    assert warm[1] < unscreened[1] and warm[2:5] == unscreened[2:5]


def test_the_weights_make_the_first_estimate_count_the_work_left():
    weights = step_lengths(CANDS, 2, True, 0, step_s=100.0, compile_s=90.0)
    left = TimeLeft(0.0)
    left.expect(weights)
    est, _ = left.update(1, len(weights), 100.0)
    assert est == pytest.approx(sum(weights[1:]))  # s: the weights are seconds
    # the same 100 s first step with nothing compiled in it is a 100 s fit: the fits and
    # the horizon after it are 10 times longer than after a first step of 90 s compiling
    slow = step_lengths(CANDS, 2, True, 0, step_s=100.0, compile_s=0.0)
    left = TimeLeft(0.0)
    left.expect(slow)
    assert left.update(1, len(slow), 100.0)[0] > 4 * est


def test_the_search_tells_the_display_before_its_first_estimate():
    import airbearing as ab

    rng = np.random.default_rng(4)
    t = np.arange(300) * 0.1  # 30 s at the rig's 10 Hz
    yaw = 20.0 * (1.0 - np.exp(-t / 20.0)) + 1e-3 * rng.normal(size=t.size)  # a coast
    log = Log(pd.DataFrame({"t": t, "yaw": yaw}), "<coast>", ROTOR)
    seen, told = [], []

    class Display:
        def __call__(self, what, done=None, total=None):
            seen.append((done, total))

        def expect(self, weights):
            told.append((len(seen), list(weights)))

    ab.discrepancy(ROTOR, [log], only="viscous_friction", max_effects=1, progress=Display())
    ((at, weights),) = told
    # one weight per step, told while the first step is still running (not yet counted)
    assert len(weights) == seen[-1][1]
    assert all(done == 0 for done, _ in seen[:at]) and seen[at][0] == 1
    assert all(w > 0 for w in weights)


def test_no_estimate_before_the_share_of_work_asked_for():
    # the demo's first sections: one second of a run whose sections weigh 1:4:36:330 s;
    # extrapolating that second would carry its jitter a hundredfold into the whole
    left = TimeLeft(0.0)
    left.expect([1.0, 4.0, 36.0, 330.0], min_share=0.05)
    assert left.update(1, 4, 1.0) is None
    assert left.update(2, 4, 5.0) is None  # 5 of 371: 1.3 %
    est, _ = left.update(3, 4, 41.0)  # 41 of 371: the pace of the work done
    assert est == pytest.approx(330.0)
    # without a share asked for, the first step sets the pace
    left = TimeLeft(0.0)
    left.expect([1.0, 4.0, 36.0, 330.0])
    assert left.update(1, 4, 1.0)[0] == pytest.approx(370.0)


def test_the_demo_asks_for_a_share_before_its_first_estimate(monkeypatch):
    import airbearing as ab
    from airbearing.reporting import demo

    told = []

    class Display:
        def __call__(self, what, done=None, total=None):
            raise KeyboardInterrupt  # stop at the first section: only the telling matters

        def expect(self, weights, min_share=0.0):
            told.append(min_share)

    with pytest.raises(KeyboardInterrupt):
        ab.run_demo("unused", quick=True, progress=Display())
    assert told == [demo.FIRST_ESTIMATE_SHARE]
    # in a full demo (warm or first run) the first two sections weigh less than that
    # share: their pace, a second or two of imports and tables, does not set the estimate
    # (in --quick, 8 % of a shorter run, the second does)
    for col in (0, 1):
        w = [demo.SECTION_COST[t][col] for t, _ in demo.SECTIONS]
        assert sum(w[:2]) < demo.FIRST_ESTIMATE_SHARE * sum(w) <= sum(w[:3])
