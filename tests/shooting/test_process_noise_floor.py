"""The process noise's floor: what the replay's integration error and the weights' noise
explain is no missing torque (:func:`.process_noise_floor.intensity_floor`, :func:`.above_floor`).

Seed 000's tabletop coasting down from 2 rad/s with drag and Coulomb friction and an exact
attitude, replayed with the truth as its nominal model: nothing is missing, but at too few
sub-steps the friction's sign turning within a sub-step makes defects no torque made.
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

import airbearing as ab
from airbearing.analysis.discrepancy.adequacy import PROCESS_NOISE_KEYS
from airbearing.analysis.discrepancy.horizon import _floored
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.shooting.penalty import _sigma_of_kappa, piece_durations
from airbearing.analysis.shooting.process_noise import SIGNIFICANCE, estimate_process_noise
from airbearing.analysis.shooting.process_noise_floor import above_floor, intensity_floor
from airbearing.io import testbed as tb_io  # (its names start with test)

TRUTH = {"coulomb_friction": 3e-5, "aero_drag": 2e-5}  # N m, N m s^2 (hidden_cases_cli's)


def _spin(substeps: int, torque_noise: float = 0.0):
    """The truth's replay of a 60 s exact-attitude spin-down at ``substeps`` (CasADi's
    virtual machine), its process noise estimated: ``(problem, fit, bounds)``."""
    tb = ab.load_testbed("seed000-tabletop")
    if torque_noise:  # a white torque the model does not hold, N m per axis
        d = tb_io.testbed_to_dict(tb)
        d["body"]["torque_noise"] = torque_noise
        tb = tb_io.testbed_from_dict(d)
    run = ab.spindown(tb, initial_rate=2.0, duration=60.0, effects=TRUTH, attitude_noise=0.0)
    datas, windows, floor = prepare(tb, [run.log])
    model = model_for(tb, TRUTH)
    problem = problem_for(model, datas, windows, floor, substeps=substeps, jit=False)
    fit = estimate_process_noise(problem, model.p0.copy(), measurement=False)
    return problem, fit, (model.p0.copy(), None, None, None)


@pytest.fixture(scope="module")
def coarse():
    return _spin(2)


def test_integration_error_alone_is_significant_against_the_bottom_of_the_grid(coarse):
    # the false alarm: the model is the truth, the test fires on the integrator's error
    _, fit, _ = coarse
    pn = fit.extra["process_noise"]
    assert pn["significant"] and pn["lr"] > 1e3, pn


def test_the_floor_explains_the_integration_error(coarse):
    problem, fit, bounds = coarse
    floor = intensity_floor(problem, fit)
    kappa = fit.extra["process_noise"]["kappa"]
    # the integrator's defects need about the intensity the test found (0.46 of it)
    assert 0.1 * kappa < floor < 10 * kappa
    out = above_floor(problem, fit, 0, bounds, floor)
    pn = out.extra["process_noise"]
    assert not pn["significant"] and pn["p"] >= SIGNIFICANCE, pn
    assert pn["horizon_s"] is None and pn["floor_kappa"] == floor
    assert pn["lr_bottom"] == fit.extra["process_noise"]["lr"]  # the old statistic kept
    assert problem.process_noise[0] == kappa  # the problem left at the fit's intensity


def test_the_noise_part_of_the_floor_is_the_intensity_whose_horizon_is_the_log(coarse):
    # (T / L)^3: a random walk of that intensity moves the attitude by one noise sigma over
    # the longest segment (60 s: one segment); below it no output moves by its noise
    problem, fit, _ = coarse
    T = float(np.mean(piece_durations(problem)[:-1]))
    L = float(piece_durations(problem).sum())
    kappa = (T / L) ** 3
    sw = _sigma_of_kappa(problem, kappa)
    assert (3 * problem.sigma_att**2 / sw**2) ** (1 / 3) == pytest.approx(L, rel=1e-9)
    # ... and the floor is at least that (the integration's part adds to it)
    assert intensity_floor(problem, fit) >= kappa


def test_a_process_noise_not_significant_is_left_alone(coarse):
    problem, fit, bounds = coarse
    pn = {**fit.extra["process_noise"], "significant": False}
    quiet = replace(fit, extra={**fit.extra, "process_noise": pn})
    assert above_floor(problem, quiet, 0, bounds, 1e3) is quiet
    # nor is a floor below every intensity tried (the test against the bottom is the same)
    assert above_floor(problem, fit, 0, bounds, 1e-9) is fit


def test_the_search_judges_its_process_noise_against_the_floor(coarse):
    # the discrepancy search's last step (nothing named here: the truth is the nominal)
    problem, fit, _ = coarse
    nothing = {"S": None, "theta0": None, "lower": None, "upper": None}
    search = SimpleNamespace(free=lambda lag, chosen, theta: nothing)
    out = _floored(search, SimpleNamespace(lag=False, chosen=[]), problem, fit)
    assert not out.extra["process_noise"]["significant"]
    assert fit.extra["process_noise"]["significant"]  # (the fit itself is not changed)
    # the JSON says which floor withdrew which statistic
    pn = out.extra["process_noise"]
    assert {"floor_kappa", "lr_bottom"} <= set(PROCESS_NOISE_KEYS)
    assert pn["lr_bottom"] == fit.extra["process_noise"]["lr"] and pn["floor_kappa"] > 0


@pytest.mark.slow
def test_at_eight_sub_steps_the_floor_holds_the_integrator_and_not_a_real_torque():
    # 8 sub-steps (the nominal model's number on this spin): the integration error alone
    # still fires (LR 17, kappa 1e-3) under a floor of 4.8e-3 (the log's 4.6e-3 and the
    # integrator's 1.5e-4); a white torque of 1e-7 N m per axis (kappa 0.1: the model
    # predicts to the noise over 22 s of the 60 s log) stays significant above it (LR 106
    # against the floor; the test against the bottom of the grid, LR 1408, stands)
    problem, fit, bounds = _spin(8)
    assert fit.extra["process_noise"]["significant"]
    floor = intensity_floor(problem, fit)
    assert not above_floor(problem, fit, 0, bounds, floor).extra["process_noise"]["significant"]
    problem, fit, bounds = _spin(8, torque_noise=1e-7)
    floor = intensity_floor(problem, fit)
    pn = above_floor(problem, fit, 0, bounds, floor).extra["process_noise"]
    assert pn["significant"] and pn["lr"] > 50, pn
