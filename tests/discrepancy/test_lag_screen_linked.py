"""The rate-sensor lag's score test on linked pieces (``discrepancy.lag_score``).

On a three-axis platform log (linked pieces, the process noise penalising their defects)
the search judges the lag on the lag-free fit when its bound says it cannot be named (the
lag Model is then neither built nor fitted), and fits it by IPOPT when it could be: a
simulated free oscillation without a lag, and the same with a lag of one sample.
"""

from __future__ import annotations

import pytest

from airbearing.analysis.discrepancy.screen import SCREEN_FRACTION
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.testbed import load_testbed

PLATFORM = load_testbed("platform-3dof")
#: the lag and a cheap screened companion (the round's shared Jacobian needs one)
ONLY = ["sensor_lag", "gyro_bias"]


def _log(effects):
    return free_oscillation(
        PLATFORM,
        initial_rate=(0.3676, 0.1265, -1.4835),
        q0=(0.99458, 0.024955, -0.014973, 0.099819),
        sliders=(0.003, -0.002, 0.004),
        effects=effects,
        seed=21,
        attitude_noise=1e-3,
        duration=20.0,
    ).log


def _lag(d):
    (c,) = [c for c in d.candidates if c.name == "sensor_lag"]
    return c


def test_a_lag_that_cannot_be_named_is_not_fitted_on_linked_pieces():
    log = _log({})
    fast = discrepancy(PLATFORM, log, only=ONLY, max_effects=1)
    assert fast.windows.linked and fast.nominal_problem.penalty is not None
    lag = _lag(fast)
    assert "the lag model was not fitted" in lag.note, lag.note
    assert not lag.nameable and not lag.significant
    assert "sensor_lag" not in fast.effects
    # the IPOPT fit of the lag Model names nothing either, and its likelihood ratio stays
    # within the factor the screen keeps for the nonlinearity of its linearised bound
    full = discrepancy(PLATFORM, log, only=ONLY, max_effects=1, screen=False)
    ref = _lag(full)
    assert "not fitted" not in ref.note and not ref.nameable
    assert ref.lr <= lag.lr / SCREEN_FRACTION


def test_a_lag_that_can_be_named_is_fitted_on_linked_pieces():
    # one sample (50 ms at 20 Hz): the first-order bound cannot rule it out
    d = discrepancy(PLATFORM, _log({"sensor_lag": 0.05}), only=ONLY, max_effects=1)
    lag = _lag(d)
    assert "not fitted" not in lag.note and lag.status == "converged"
    # the simulated value to well within the 1e-3 relative the noise allows (its std ~1e-4 s)
    assert d.effects["sensor_lag"] == pytest.approx(0.05, rel=0.01)
