"""The Kalman likelihood of a dof-1 log (analysis/shooting/kalman.py).

Oracles: recovery of the effects, the measurement noise and the process-noise intensity
hidden in simulated coast-downs (within 3 of the fit's own standard errors: the observed
information is the estimator's asymptotic covariance, so a correct fit misses by more than
3 sigma in 0.3 % of logs); an independent NumPy filter (the same Model step and Jacobians
from CasADi, the predict/update/skip logic re-derived in plain NumPy) for the likelihood
itself, missing rows and restarts included; central differences as a sanity check of the
exact gradient and Hessian.

The process torque of the simulation is white and held over each sample (``torque_noise``
N m, 1 sigma per sample of ``dt``), so the rate random-walk intensity it makes is
``sigma_w = torque_noise sqrt(dt) / J`` (the rate's increment over ``dt`` has variance
``(torque_noise dt / J)^2 = sigma_w^2 dt``).
"""

from __future__ import annotations

import dataclasses
import math

import casadi as ca
import numpy as np
import pytest
from rigs import ROTOR

from airbearing.analysis.shooting.kalman import (
    P0_ATTITUDE,
    P0_RATE,
    KalmanData,
    fit_kalman,
    kalman_data,
    kalman_nll,
)
from airbearing.analysis.shooting.logs import replay_data
from airbearing.analysis.simulation.artefacts import sample_times, with_gap, with_glitches
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.analysis.simulation.scenarios import spindown
from airbearing.errors import InputError
from airbearing.io.testbed import testbed_from_dict as make_testbed
from airbearing.models.model import build_model

# the mocap rig (yaw only, 10 Hz, 1 mrad) and a gyro rig (rate only, 20 Hz, 0.15 mrad/s)
GYRO_ROTOR = make_testbed(
    {
        "kind": "platform",
        "name": "gyro-rotor",
        "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
        "sensors": {"rate": 20.0, "gyro": True, "gyro_noise": 1.5e-4},
    }
)
FREE = ["viscous_friction", "coulomb_friction"]
TRUTH = {"viscous_friction": 2e-5, "coulomb_friction": 1e-5}  # N m s/rad, N m
START = {"viscous_friction": 1e-5, "coulomb_friction": 0.0}


def _with_torque_noise(tb, sigma_w):
    """The testbed with the white torque (N m per sample) of rate intensity ``sigma_w``."""
    tau = sigma_w * tb.body.yaw_inertia / math.sqrt(tb.sensors.dt)
    return tb.replace(body=dataclasses.replace(tb.body, torque_noise=tau))


def _log(tb, *, duration, seed, sigma_w=0.0, rate=2.0):
    run = spindown(
        _with_torque_noise(tb, sigma_w), initial_rate=rate, duration=duration, effects=TRUTH,
        seed=seed,
    )  # fmt: skip
    return replay_data(tb, run.log)


def _within(est, sd, truth, k=3.0):
    return abs(est - truth) <= k * sd


# ------------------------------------------------------------------ recovery


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_recovers_hidden_friction_and_noise_on_a_mocap_coast_down():
    data = _log(ROTOR, duration=120.0, seed=3)
    # a Log is read through the engine's front end (the same rows as ReplayData)
    fit = fit_kalman(build_model(ROTOR, START), data.log, FREE)
    for name in FREE:
        est, sd = fit.estimate(name)
        assert sd > 0 and _within(est, sd, TRUTH[name]), (name, est, sd)
    # the log's yaw noise is the testbed's attitude_noise, 1 mrad
    assert _within(fit.noise["yaw"], fit.noise_std["yaw"], ROTOR.sensors.attitude_noise)
    assert fit.rows == data.n == fit.observations
    assert math.isfinite(fit.nll) and fit.iterations > 0


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_recovers_a_hidden_process_torque_intensity_on_a_gyro_coast_down():
    sigma_w = 1e-4  # rad/s per sqrt(s): 0.7 noise sigma of rate wander per second
    data = _log(GYRO_ROTOR, duration=60.0, seed=5, sigma_w=sigma_w)
    fit = fit_kalman(build_model(GYRO_ROTOR, START), data, FREE, test_intensity=True)
    assert fit.significant and fit.lr > 100  # a torque of 0.7 noise sigma per second
    assert fit.intensity_std > 0
    assert _within(fit.intensity, fit.intensity_std, sigma_w), (fit.intensity, fit.intensity_std)
    assert _within(fit.noise["wz"], fit.noise_std["wz"], GYRO_ROTOR.sensors.gyro_noise)
    for name in FREE:
        est, sd = fit.estimate(name)
        assert _within(est, sd, TRUTH[name]), (name, est, sd)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_no_process_torque_gives_an_intensity_far_below_and_not_significant():
    # on the same log without a torque the intensity collapses: below a tenth of the one
    # the previous test finds (10 of its standard errors away from it)
    data = _log(GYRO_ROTOR, duration=60.0, seed=5)
    fit = fit_kalman(build_model(GYRO_ROTOR, START), data, FREE, test_intensity=True)
    assert fit.intensity < 1e-5
    # and the likelihood-ratio test does not call it significant (p >= 1e-3: a correct
    # test errs so on one log in a thousand)
    assert fit.significant is False and fit.p >= 1e-3


def test_fixed_intensity_and_noise_are_not_estimated():
    data = _log(ROTOR, duration=60.0, seed=4)
    fit = fit_kalman(build_model(ROTOR, START), data, FREE, intensity=0.0, noise={"yaw": 1e-3})
    assert fit.intensity == 0.0 and math.isnan(fit.intensity_std)
    assert fit.noise == {"yaw": 1e-3} and math.isnan(fit.noise_std["yaw"])
    doc = fit.to_json()
    assert fit.significant is None and doc["p"] is None  # not tested: fixed intensity
    assert doc["intensity_std"] is None and doc["noise_std"] == {"yaw": None}
    assert [e["name"] for e in doc["effects"]] == FREE
    for name in FREE:
        est, sd = fit.estimate(name)
        assert _within(est, sd, TRUTH[name])


def test_a_gap_restarts_the_filter_and_outliers_are_skipped():
    # 60 s at 20 Hz with a 5 s gap and two gyro spikes of 100 noise sigmas: the front end
    # makes two segments and marks the spikes; the filter restarts at the second segment
    # and reads nothing of the spikes, so the truth is still recovered
    t, _ = with_gap(sample_times(GYRO_ROTOR, 60.0), 30.0, 5.0)
    log = simulate_on_times(GYRO_ROTOR, t, initial_rate=2.0, effects=TRUTH, seed=11)
    log, spikes = with_glitches(log, [200, 700], "rate_spike", size=100 * 1.5e-4)
    data = replay_data(GYRO_ROTOR, log)
    assert len(data.segments) == 2 and set(spikes) <= set(data.outlier_rows)
    model = build_model(GYRO_ROTOR, START)
    kd = kalman_data(data, model)
    assert np.flatnonzero(kd.reset).tolist() == [a for a, _ in data.segments]
    assert np.isnan(kd.y[list(spikes)]).all()
    fit = fit_kalman(model, data, FREE)
    assert fit.observations == data.n - len(data.outlier_rows)
    for name in FREE:
        est, sd = fit.estimate(name)
        assert _within(est, sd, TRUTH[name]), (name, est, sd)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_a_lagged_gyro_is_a_state_of_the_filter():
    # sensor_lag adds a lagged-rate state whose exact update divides by the interval: the
    # restarts and the padding (no interval) must not make the likelihood NaN
    truth = {**TRUTH, "sensor_lag": 0.2}  # s
    run = spindown(GYRO_ROTOR, initial_rate=2.0, duration=30.0, effects=truth, seed=2)
    model = build_model(GYRO_ROTOR, {**START, "sensor_lag": 0.1})
    assert model.x_names == ("yaw", "wz", "lag_wz")
    fit = fit_kalman(model, run.log, [*FREE, "sensor_lag"], intensity=0.0)
    for name in [*FREE, "sensor_lag"]:
        est, sd = fit.estimate(name)
        assert _within(est, sd, truth[name]), (name, est, sd)


@pytest.mark.slow
def test_three_sigma_intervals_cover_the_truth():
    # 20 seeds of a 40 s mocap coast-down: each interval covers with probability 0.997
    # if the errors are right; >= 18 of 20 fails with probability < 1e-3 for a coverage
    # of 0.997 and passes with probability 0.6 even for 0.9: it catches standard errors
    # that are badly too small (the usual failure), not a slight misfit
    hits = 0
    model = build_model(ROTOR, {**START, "coulomb_friction": TRUTH["coulomb_friction"]})
    for seed in range(20):
        fit = fit_kalman(model, _log(ROTOR, duration=40.0, seed=100 + seed), ["viscous_friction"])
        est, sd = fit.estimate("viscous_friction")
        hits += _within(est, sd, TRUTH["viscous_friction"])
    assert hits >= 18, hits


# ------------------------------------------------------------------ the likelihood itself


def _numpy_nll(model, kd: KalmanData, p, sigma_w, noise, substeps=2):
    """The filter in plain NumPy: the Model's step and its Jacobians from CasADi, the
    predict, the held-torque covariance, the update with missing entries skipped, and the
    restarts written out again (module doc of kalman.py)."""
    x, u, dt = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("dt")
    pp = ca.DM(p)
    xn = model.step_dt(substeps)(x, u, pp, dt)
    it = model.index("tau_z", "u")[0]
    step = ca.Function("s", [x, u, dt], [xn, ca.jacobian(xn, x), ca.jacobian(xn, u[it])])
    b = ca.Function("b", [x, u], [ca.jacobian(model.f(x, u, pp)[1], u[it])])
    rows = model.index(list(kd.y_names), "y")
    yh = model.h(x, u, pp)[rows]
    meas = ca.Function("h", [x, u], [yh, ca.jacobian(yh, x)])
    R = np.diag([noise[k] ** 2 for k in kd.y_names])
    nll = 0.0
    for k in range(kd.n):
        if kd.reset[k]:
            xk = kd.start[k].copy()
            P = np.diag([P0_ATTITUDE**2, P0_RATE**2])
        else:
            h = kd.t[k] - kd.t[k - 1]
            xn_, F, G = (np.array(v) for v in step(xk, kd.u[k - 1], h))
            g = G / float(b(xk, kd.u[k - 1]))
            xk = xn_.ravel()
            P = F @ P @ F.T + sigma_w**2 * (g @ g.T) / h
        ok = np.isfinite(kd.y[k])
        if not ok.any():
            continue
        yk, H = (np.array(v) for v in meas(xk, kd.u[k]))
        H, e = H[ok], (kd.y[k] - yk.ravel())[ok]
        S = H @ P @ H.T + R[np.ix_(ok, ok)]
        K = P @ H.T @ np.linalg.inv(S)
        xk = xk + K @ e
        P = (np.eye(len(xk)) - K @ H) @ P
        nll += 0.5 * (
            np.log(np.linalg.det(S)) + e @ np.linalg.solve(S, e) + ok.sum() * np.log(2 * np.pi)
        )
    return nll


def test_likelihood_equals_a_numpy_filter_with_missing_rows_and_a_restart():
    data = _log(GYRO_ROTOR, duration=4.0, seed=7, sigma_w=1e-4)
    model = build_model(GYRO_ROTOR, TRUTH)
    kd = kalman_data(data, model).without([5, 6, 7, 30, 79])
    reset = kd.reset.copy()
    reset[40] = True  # a second segment from the measured state at row 40
    start = kd.start.copy()
    start[40] = [data.yaw[40], data.w[40, 0]]
    kd = dataclasses.replace(kd, reset=reset, start=start)
    noise = {"wz": 1.5e-4}
    want = _numpy_nll(model, kd, model.p0, 1e-4, noise)
    got = kalman_nll(model, kd, intensity=1e-4, noise=noise)
    # same arithmetic in another order: round-off of ~80 updates of O(1e3) nats each
    assert got == pytest.approx(want, rel=1e-10, abs=1e-8)
    # the skipped rows add nothing: putting a wild value there changes nothing
    y = kd.y.copy()
    assert np.isnan(y[30, 0])
    # and the oracle is not blind to those rows: filled in, they change the likelihood
    complete = kalman_nll(model, dataclasses.replace(kd, y=np.nan_to_num(y, nan=5.0)),
                          intensity=1e-4, noise=noise)  # fmt: skip
    assert complete != got


def test_exact_gradient_and_hessian_agree_with_central_differences():
    # a sanity check of the forward sensitivities (the derivatives are CasADi's)
    data = _log(ROTOR, duration=6.0, seed=2, sigma_w=1e-3)
    model = build_model(ROTOR, TRUTH)
    noise = {"yaw": 1.2e-3}
    f, g, H = kalman_nll(model, data, intensity=8e-4, noise=noise, order=2)
    p = model.p0
    z = np.r_[p, math.log(8e-4), math.log(1.2e-3)]

    def at(zz, order):
        return kalman_nll(model, data, p=zz[: model.n_p], intensity=math.exp(zz[-2]),
                          noise={"yaw": math.exp(zz[-1])}, order=order)  # fmt: skip

    for i in [model.p_names.index(n) for n in FREE] + [model.n_p, model.n_p + 1]:
        h = 1e-4 * max(abs(z[i]), 1e-4) if i < model.n_p else 1e-4
        e = np.zeros_like(z)
        e[i] = h
        fd = (at(z + e, 0) - at(z - e, 0)) / (2 * h)
        # central difference: truncation O(h^2), round-off ~1e-13 |f| / h
        assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-12 * abs(f) / h)
        gd = (at(z + e, 1)[1] - at(z - e, 1)[1]) / (2 * h)
        np.testing.assert_allclose(H[i], gd, rtol=1e-4, atol=1e-6 * np.max(np.abs(H[i])))
    np.testing.assert_allclose(H, H.T, rtol=1e-9, atol=1e-12 * np.max(np.abs(H)))


# ------------------------------------------------------------------ bad input


def test_bad_input_is_one_line():
    data = _log(ROTOR, duration=6.0, seed=1)
    model = build_model(ROTOR, START)
    cases = [
        (lambda: fit_kalman(model, data, ["viscous"]), "viscous"),
        (lambda: fit_kalman(model, data, FREE, noise={"wz": 1e-3}), "wz"),
        (lambda: fit_kalman(model, data, FREE, intensity=-1.0), "intensity"),
        (lambda: fit_kalman(build_model("platform-3dof"), data, []), "dof = 3"),
        (lambda: kalman_nll(model, data, noise={}), "yaw"),
    ]
    for call, word in cases:
        with pytest.raises(InputError, match=word) as err:
            call()
        assert "\n" not in str(err.value)
