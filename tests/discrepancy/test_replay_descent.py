"""Replay's descent of the process-noise grid ends once the likelihood has clearly peaked.

Below a torque the Model misses, each lower intensity ties the pieces closer to one
trajectory that does not follow the data: the likelihood falls by orders of magnitude and
the IPOPT fits there are the costliest of a replay. Oracle: the whole descent of the same
problem (``stop_when_peaked=False``), which must choose the same intensity and fit.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import airbearing as ab
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    PEAK_DROP,
    PEAK_FALLS,
    estimate_process_noise,
    peaked,
)

CMG = ab.load_testbed("cmg-yaw")


def test_the_drop_settles_the_significance_test_to_double_precision():
    # the test against the lowest intensity reached (a 50:50 mixture of chi2(0) and
    # chi2(1), process_noise's module doc) already has p = 0: no lower one changes it
    assert 0.5 * stats.chi2.sf(2.0 * PEAK_DROP, 1) == 0.0
    assert PEAK_FALLS >= 2


@pytest.mark.parametrize(
    ("lls", "expected"),
    [
        ([-10.0, -5.0, -1e4], False),  # one fall only
        ([-10.0, -1e4, -1e5], True),  # two falls, far below the best
        ([-1e3, -1e3 - 10.0, -1e3 - 20.0], False),  # falling, but by less than the drop
        ([-10.0, -1e4, -1e5, -1e5 + 1.0], False),  # the last rose again
        ([-432.0, -422.8, -413.6, -406.3, -406.33, -406.38], False),  # a flat bottom
        ([-1e4, -10.0, -1e3, -2e3], True),  # a peak inside the grid
    ],
)
def test_peaked_needs_successive_falls_far_below_the_best(lls, expected):
    assert peaked(lls) is expected


def _descent(log, stop: bool):
    datas, windows, floor = prepare(CMG, [log])
    model = model_for(CMG)
    problem = problem_for(model, datas, windows, floor, theta_slots=0)
    fit = problem.fit(model.p0)
    return estimate_process_noise(problem, model.p0, start=fit, stop_when_peaked=stop)


def test_a_torque_the_model_misses_ends_the_descent_with_the_same_answer():
    log = ab.slew(CMG, angle_deg=30.0, duration=3.0, effects={"viscous_friction": 2e-4}).log
    whole, short = _descent(log, False), _descent(log, True)
    pw, ps = whole.extra["process_noise"], short.extra["process_noise"]
    assert pw["kappa_whole"] == KAPPA_GRID[-1]
    assert ps["kappa_whole"] > KAPPA_GRID[-1], ps  # the descent ended early
    assert peaked([ps["loglik"][k] for k in KAPPA_GRID if k >= ps["kappa_whole"]])
    # the same most likely intensity, fit and verdict (the same fits to that point)
    for key in ("kappa", "intensity", "p", "significant", "horizon_s", "gap_short"):
        assert ps[key] == pw[key], key
    assert short.gap == whole.gap
    np.testing.assert_array_equal(short.delta, whole.delta)
    # the intensities reached have the same likelihoods; the test against the lowest
    # reached is the weaker one
    for k in KAPPA_GRID:
        if k in ps["loglik"]:
            assert ps["loglik"][k] == pw["loglik"][k], k
    assert 0.0 < ps["lr"] <= pw["lr"]


def test_a_model_that_explains_the_log_descends_to_the_bottom():
    log = ab.slew(CMG, angle_deg=30.0, duration=3.0).log
    pn = ab.replay(CMG, log).process_noise
    assert pn["kappa_whole"] == KAPPA_GRID[-1], pn
    assert not pn["significant"], pn
