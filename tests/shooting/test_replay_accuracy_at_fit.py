"""The replay's integration accuracy rule checked at given parameters (a fit's), not only
the nominal.

A discrepancy search's Model holds every candidate at zero; a Coulomb friction's smoothed
sign turns within a sub-step whenever a body rate crosses zero, so the fitted model can
need many more sub-steps than the nominal one on a noise-free attitude.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import airbearing as ab
from airbearing.analysis.discrepancy.horizon import _accurate_at_fit
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.shooting.accuracy import MAX_SUBSTEPS, integration_error, substeps_for
from airbearing.analysis.shooting.logs import ATTITUDE_SIGMA_MIN

TRUTH = {"coulomb_friction": 1e-5, "aero_drag": 5e-6}  # N m, N m s^2/rad^2


@pytest.fixture(scope="module")
def spin_logs():
    """Seed 000's tabletop spun down from 2 rad/s for 10 s with the frictions hidden and a
    noise-free attitude (gyro noise on): the replay's data, windows and noise floor."""
    tb = ab.load_testbed("seed000-tabletop")
    run = ab.spindown(tb, initial_rate=2.0, duration=10.0, effects=TRUTH, attitude_noise=0.0)
    return tb, *prepare(tb, [run.log])


@pytest.fixture(scope="module")
def spin(spin_logs):
    """The spin's windows and floor, the search's Model (both frictions at zero) and the
    truth's parameters."""
    tb, _, windows, floor = spin_logs
    model = model_for(tb, dict.fromkeys(TRUTH, 0.0))
    p = model.p0.copy()
    p[model.index(list(TRUTH), "p")] = list(TRUTH.values())
    return model, windows, floor, p


def test_the_fitted_frictions_need_more_sub_steps_than_the_nominal_model(spin):
    model, windows, floor, p = spin
    nominal = substeps_for(model, windows, floor)
    at_fit = substeps_for(model, windows, floor, p=p)
    assert at_fit > nominal
    # the nominal number leaves the frictions' integration error over a segment above the
    # attitude's resolution itself (the rule's tolerance is that over sqrt(n) samples), the
    # nominal model's far below it
    assert integration_error(model, windows, nominal, p)[0] > ATTITUDE_SIGMA_MIN
    assert integration_error(model, windows, nominal)[0] < ATTITUDE_SIGMA_MIN
    # more sub-steps shrink it (the check doubles until within tolerance or at the cap)
    assert at_fit <= MAX_SUBSTEPS
    assert integration_error(model, windows, at_fit, p)[0] < ATTITUDE_SIGMA_MIN


def test_the_nominal_parameters_ask_what_no_parameters_ask(spin):
    # the cache is keyed by the parameters: the nominal answer is not the fit's, nor
    # the reverse, whichever is asked first
    model, windows, floor, p = spin
    assert substeps_for(model, windows, floor, p=model.p0) == substeps_for(model, windows, floor)
    assert substeps_for(model, windows, floor, p=np.array(p)) > substeps_for(
        model, windows, floor, p=model.p0
    )


@pytest.fixture(scope="module")
def nominal_fit(spin, spin_logs):
    """The frictions fitted on the spin's linked pieces at the nominal model's sub-steps
    (CasADi's virtual machine: no compilation in the test), with what the search's final
    stage hands over: the search's noise floor, logs, free-parameter layout and choice."""
    model, windows, floor, _ = spin
    datas = spin_logs[1]
    problem = problem_for(model, datas, windows, floor, jit=False)
    S = np.zeros((model.n_p, 2))
    S[model.index(list(TRUTH), "p"), [0, 1]] = 1.0
    free = {"S": S, "theta0": np.array(list(TRUTH.values())), "lower": np.zeros(2),
            "upper": np.full(2, np.inf)}  # fmt: skip
    current = problem.fit(model.p0.copy(), **free)
    search = SimpleNamespace(floor=floor, datas=datas, free=lambda lag, chosen, theta: free)
    return search, problem, current


def test_a_fit_that_needs_no_more_sub_steps_is_handed_back_as_it_is(nominal_fit):
    search, problem, current = nominal_fit
    # nothing named: the nominal model's check is the fit's
    out = _accurate_at_fit(search, SimpleNamespace(chosen=[], lag=False), problem, current)
    assert out[0] is problem and out[1] is current


def test_the_named_effects_are_refitted_at_the_sub_steps_their_values_need(nominal_fit, spin):
    model, windows, floor, _ = spin
    search, problem, current = nominal_fit
    sel = SimpleNamespace(chosen=["coulomb_friction", "aero_drag"], lag=False)
    accurate, refit = _accurate_at_fit(search, sel, problem, current)
    need = substeps_for(model, windows, floor, p=current.p)
    assert accurate.substeps == need > problem.substeps
    assert accurate.jit is False  # one refit: the virtual machine, no C compilation
    # refitted there from the nominal fit: a converged fit of the same effects
    assert refit.level == "converged" and refit.theta.shape == current.theta.shape
    assert not np.array_equal(refit.theta, current.theta)
