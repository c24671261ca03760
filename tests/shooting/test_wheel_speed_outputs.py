"""The logged wheel speeds are fitted outputs of the shooting engine (output group ``ws``).

FORMATS.md: ``ws_i`` is the wheel speed ``W_i`` relative to the body (rad/s), the Model's
output ``ws_i``. A reaction-wheel log compares it at every sample with its own noise level
(the fourth differences of the wheel's absolute speed less the commanded torque's
integral), and each window fits its start. What acts on a wheel alone then shows where it
acts: on ``rw-yaw`` (J_zz = 0.02 kg m^2, Iw = 2.865e-5 kg m^2) a 10 % wheel inertia error
changes the table's rate by a part in 7000 (``J - Iw``) but the wheel's own acceleration
``tau / Iw`` by 10 %. The old engine fitted the body's outputs only: the same log gave a
likelihood ratio of 3.4 against the 10.8 of p = 1e-3.

The tests fit one rw-yaw slew on free 10 s windows, with and without the effect's
parameter free, and compare the likelihood ratio (the drop of the residual's sum of
squares in noise units) with the chi-square(1) threshold of p = 1e-3
(``scipy.stats.chi2.isf``).
"""

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

import airbearing as ab
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.io import testbed as testbed_io
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed

SPEED_NOISE = 0.01  # rad/s, the built-in rw-yaw's wheels.speed_noise
THRESHOLD = float(chi2.isf(1e-3, 1))  # 10.83
DURATION = 20.0  # s: a 60 deg slew and its settling, two 10 s windows
WINDOW_S = 10.0


def _slew(effects, seed):
    tb = load_testbed("rw-yaw")
    log = ab.slew(tb, angle_deg=60.0, duration=DURATION, seed=seed, effects=effects).log
    return tb, log


def _likelihood_ratio(tb, log, name):
    """The nominal fit's and the fit with ``name`` free: their residuals' sums of squares
    (noise units) differ by the likelihood ratio; also the problem and the free fit."""
    datas, windows, floor = prepare(tb, [log], window_s=WINDOW_S)
    model = model_for(tb, {name: 0.0})
    problem = problem_for(model, datas, windows, floor, jit=False, theta_slots=1)
    nominal = problem.fit(model.p0, name="nominal")
    S = np.zeros((model.n_p, 1))
    S[model.index(name, "p")[0], 0] = 1.0
    free = problem.fit(model.p0, S, np.zeros(1), delta0=nominal.delta, name=name)
    return nominal.rss - free.rss, problem, free


@pytest.fixture(scope="module")
def inertia_case():
    tb, log = _slew({"wheel_inertia_error": 0.1}, seed=5)
    return _likelihood_ratio(tb, log, "wheel_inertia_error")


def test_the_wheel_speeds_are_an_output_group_with_their_own_noise(inertia_case):
    _, problem, fit = inertia_case
    assert problem.outputs == ("rate", "ws")
    # one start per window for the wheel speed, as for the rate
    assert (problem.n_rate, problem.n_ws) == (1, 1)
    # the weight is the data's own noise estimate: within 15 % of the simulated 0.01 rad/s
    # (a MAD of about 400 fourth differences: 1.5 x 1/sqrt(400) = 7.5 % at one sigma)
    assert problem.sigma_ws == pytest.approx(SPEED_NOISE, rel=0.15)
    # at the fitted effect the wheel residual is the noise (same 15 %)
    assert problem.noise_rms(fit.extra["r"])["ws"] == pytest.approx(SPEED_NOISE, rel=0.15)


def test_a_wheel_inertia_error_shows_in_the_fitted_wheel_speeds(inertia_case):
    lr, _, fit = inertia_case
    assert lr > THRESHOLD
    # and the fit finds it: 0.1 within 3 of its standard errors (and 1 %)
    assert abs(fit.theta[0] - 0.1) < max(3 * fit.theta_std[0], 1e-3)


def test_a_wheel_torque_error_shows_in_the_fitted_wheel_speeds():
    tb, log = _slew({"wheel_torque_error": 0.05}, seed=6)
    lr, _, fit = _likelihood_ratio(tb, log, "wheel_torque_error")
    assert lr > THRESHOLD
    assert abs(fit.theta[0] - 0.05) < max(3 * fit.theta_std[0], 1e-3)


def test_nothing_hidden_gives_no_wheel_effect_and_a_wheel_residual_at_the_noise():
    tb, log = _slew({}, seed=7)
    lr, problem, fit = _likelihood_ratio(tb, log, "wheel_inertia_error")
    # the chi-square(1) law: passed with probability 1e-3 when nothing is hidden
    assert lr < THRESHOLD
    assert problem.noise_rms(fit.extra["r"])["ws"] == pytest.approx(SPEED_NOISE, rel=0.15)


def test_the_wheel_speed_floor_is_the_sensor_not_the_commands_noise():
    # open-loop commands drawn afresh every sample (+-0.5 mN m, white): the wheel's slope
    # jumps by up to 0.5e-3 / 2.865e-5 = 17 rad/s^2 each sample, 0.9 rad/s per sample,
    # 90 times the sensor's noise; the floor takes the commanded torque's integral out of
    # the wheel's absolute speed and sees the sensor alone
    tb = load_testbed("rw-yaw")
    model = model_for(tb)
    n, dt = 400, tb.sensors.dt
    rng = np.random.default_rng(3)
    U = np.zeros((model.nu, n))
    U[model.index("wc1", "u")[0]] = rng.uniform(-5e-4, 5e-4, n)
    x0 = model.x0(wheels=[200.0])
    X = np.vstack([x0, np.asarray(model.rollout(n - 1, dt)(x0, U[:, :-1], model.p0)).T])
    cols = {
        "t": np.arange(n) * dt,
        "yaw": X[:, 0] + tb.sensors.attitude_noise * rng.standard_normal(n),
        "wz": X[:, 1] + tb.sensors.gyro_noise * rng.standard_normal(n),
        "ws1": X[:, 2] + SPEED_NOISE * rng.standard_normal(n),
        "wc1": U[model.index("wc1", "u")[0]],
    }
    log = Log(pd.DataFrame(cols), source="<white commands>", testbed=tb)
    _, _, floor = prepare(tb, [log], window_s=WINDOW_S)
    # about 400 fourth differences: the MAD's 7.5 % at one sigma, so 15 % is two
    assert floor.wheel == pytest.approx(SPEED_NOISE, rel=0.15)


def test_each_wheel_speed_is_weighted_by_its_own_tachometer():
    # two wheels on a yaw table (spin axes +z and -z), wheel 2's tachometer 20 x noisier
    # than wheel 1's (0.2 rad/s against the built-in's 0.01): one level for the group (their
    # RMS, 0.14 rad/s) would weight wheel 1 fourteen times too lightly and wheel 2 at 1.4 x
    # its noise; each wheel over its own level leaves both residuals at the noise
    d = testbed_io.testbed_to_dict(load_testbed("rw-yaw"))
    d["wheels"].update(
        axes=[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], speeds=[0.0, 0.0], inertia=2.865e-5
    )
    tb = testbed_io.testbed_from_dict(d)
    log = ab.slew(tb, angle_deg=60.0, duration=DURATION, seed=7).log
    data = log.data.copy()
    extra = 0.2  # rad/s
    data["ws2"] += extra * np.random.default_rng(8).standard_normal(len(data))
    log = Log(data, source="two-tachometers.csv", testbed=tb)
    datas, windows, floor = prepare(tb, [log], window_s=WINDOW_S)
    problem = problem_for(model_for(tb, {}), datas, windows, floor, jit=False)
    truth = np.array([SPEED_NOISE, np.hypot(SPEED_NOISE, extra)])
    # each level estimated within 15 % (the MAD of about 400 fourth differences, as above)
    np.testing.assert_allclose(problem.sigma_ws_axes, truth, rtol=0.15)
    fit = problem.fit(problem.model.p0, name="nominal")
    r = problem.raw_measurement(fit.extra["r"])
    sel = (problem.group == problem.outputs.index("ws")) & problem.usable
    for i in range(2):
        rows = sel & (problem.component == i)
        # noise units: RMS 1 within 15 % (about 400 rows: 3.5 % at one sigma, and the level's
        # own 7.5 %)
        assert np.sqrt(np.mean(r[rows] ** 2)) == pytest.approx(1.0, rel=0.15), i
