"""The replay's RK4 accuracy rule checked at given parameters (a fit's), not only the nominal.

A discrepancy search's Model holds every candidate at zero; a Coulomb friction's smoothed
sign turns within a sub-step whenever a body rate crosses zero, so the fitted model can
need many more sub-steps than the nominal one on a noise-free attitude.
"""

from __future__ import annotations

import numpy as np
import pytest

import airbearing as ab
from airbearing.analysis.discrepancy.replay import model_for, prepare
from airbearing.analysis.shooting.accuracy import MAX_SUBSTEPS, integration_error, substeps_for
from airbearing.analysis.shooting.logs import ATTITUDE_SIGMA_MIN

TRUTH = {"coulomb_friction": 1e-5, "aero_drag": 5e-6}  # N m, N m s^2/rad^2


@pytest.fixture(scope="module")
def spin():
    """Seed 000's tabletop spun down from 2 rad/s for 10 s with the frictions hidden and a
    noise-free attitude; the search's Model (both at zero) and the truth's parameters."""
    tb = ab.load_testbed("seed000-tabletop")
    run = ab.spindown(tb, initial_rate=2.0, duration=10.0, effects=TRUTH, attitude_noise=0.0)
    _, windows, floor = prepare(tb, [run.log])
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
