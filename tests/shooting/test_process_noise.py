"""The estimator whose horizon comes from the data: process noise, honest errors, the bound.

Reference values are physics derived here: the Fisher information of a viscous coast-down
in closed form, and the coverage of the truth by the reported standard errors.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from rigs import ROTOR
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from airbearing.analysis.discrepancy.replay import model_for, problem_for
from airbearing.analysis.shooting.errors import honest_errors, normalised_residuals
from airbearing.analysis.shooting.logs import make_windows, noise_floor, replay_data
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    defect_whitening,
    estimate_process_noise,
    set_intensity,
)
from airbearing.analysis.shooting.process_noise_floor import above_floor, intensity_floor
from airbearing.io.log import Log

J_ZZ = 0.05  # kg m^2, the rig's yaw inertia (rigs.MOCAP_RIG_TOML)
SIGMA = 1.5e-3  # rad, attitude noise of the logs
RATE_HZ = 10.0


#: s, the step of the piecewise-constant torque of the random-walk case
TORQUE_DT = 0.05


def _coast(w0, c, seconds, seed, kicks=None):
    """A passive yaw coast-down with viscous friction ``c`` (N m s) and an optional extra
    torque held at ``kicks[k]`` (N m) over ``[k, k + 1) TORQUE_DT``, yaw logged at 10 Hz
    with white noise ``SIGMA``."""
    t = np.arange(0.0, seconds, 1.0 / RATE_HZ)
    if kicks is None:

        def f(tt, x):
            return [x[1], -c * x[1] / J_ZZ]

        sol = solve_ivp(f, (0, t[-1]), [0.0, w0], t_eval=t, rtol=1e-11, atol=1e-12, max_step=0.05)
        yaw = sol.y[0]
    else:
        # linear between the torque's steps: the exact step x+ = Ad x + Bd tau, from the
        # matrix exponential of [[A, B], [0, 0]] (an adaptive integrator has to stop at each
        # of the thousands of steps: 12 s for this log)
        E = expm(
            np.array([[0.0, 1.0, 0.0], [0.0, -c / J_ZZ, 1 / J_ZZ], [0.0, 0.0, 0.0]]) * TORQUE_DT
        )
        x = np.empty((len(kicks) + 1, 2))
        x[0] = (0.0, w0)
        for k, tau in enumerate(kicks):
            x[k + 1] = E[:2, :2] @ x[k] + E[:2, 2] * tau
        per_sample = round(1.0 / (RATE_HZ * TORQUE_DT))
        yaw = x[::per_sample, 0][: t.size]
        assert yaw.size == t.size
    yaw = yaw + np.random.default_rng(seed).normal(0.0, SIGMA, t.size)
    return Log(pd.DataFrame({"t": t, "yaw": yaw}), source=f"coast{seed}.csv", testbed=ROTOR)


def _problem(logs, piece_s=5.0):
    datas = [replay_data(ROTOR, lg) for lg in logs]
    floor = noise_floor(datas)
    windows = make_windows(datas, window_s=piece_s, linked=True)
    model = model_for(ROTOR, {"viscous_friction": 0.0})
    prob = problem_for(model, datas, windows, floor)
    S = np.zeros((model.n_p, 1))
    S[model.index(["viscous_friction"], "p")[0], 0] = 1.0
    return prob, model, S


def _fisher_closed_form(w0, c, seconds, sigma):
    """Fisher information of (yaw0, w0, c) for yaw(t) = yaw0 + w0 J/c (1 - exp(-c t / J))."""
    t = np.arange(0.0, seconds, 1.0 / RATE_HZ)
    a = c / J_ZZ
    e = np.exp(-a * t)
    d_y0 = np.ones_like(t)
    d_w0 = (1 - e) / a
    # d/dc of w0 (1 - e^{-a t}) / a with a = c / J
    d_c = w0 * (t * e / a - (1 - e) / a**2) / J_ZZ
    G = np.column_stack([d_y0, d_w0, d_c])
    return G.T @ G / sigma**2


def test_whitening_inverts_the_integrated_wiener_covariance():
    prob, _, _ = _problem([_coast(1.0, 2e-5, 60.0, 1)])
    sw = 1e-5
    W, logdet = defect_whitening(prob, sw)
    # one linked pair: W Sigma W^T = I with Sigma of (yaw, rate) defects in noise units
    T = float(np.sum(prob.windows.dt[0, : prob.windows.end[0]]))
    s_a, s_r = prob.sigma_att, prob.sigma_rate
    Sig = sw**2 * np.array(
        [[T**3 / 3 / s_a**2, T**2 / 2 / (s_a * s_r)], [T**2 / 2 / (s_a * s_r), T / s_r**2]]
    )
    Wb = W[:2, :2].toarray()
    assert np.allclose(Wb @ Sig @ Wb.T, np.eye(2), atol=1e-6)
    n_pairs = int(np.sum(prob.windows.link))
    assert logdet == pytest.approx(-0.5 * n_pairs * np.log(np.linalg.det(Sig)), rel=1e-6)


def test_in_model_intensity_falls_to_the_bottom_and_std_meets_the_closed_form_bound():
    w0, c, seconds = 1.2, 2e-4, 120.0
    prob, model, S = _problem([_coast(w0, c, seconds, 7)])
    top = prob.fit(model.p0, S, np.zeros(1), name="top")
    fit = estimate_process_noise(prob, model.p0, S, top.theta, delta0=top.delta, start=top)
    pn = fit.extra["process_noise"]
    assert not pn["significant"] and pn["kappa"] == KAPPA_GRID[-1], pn
    he = honest_errors(prob, fit, 1)
    F = _fisher_closed_form(w0, c, seconds, prob.sigma_att)
    bound = float(np.sqrt(np.linalg.inv(F)[2, 2]))
    # the bound of ONE trajectory (one initial yaw and rate): the engine's own CRLB equals
    # the closed form (2 % : the noise floor is estimated from the log, not given)
    assert he.crlb[0] == pytest.approx(bound, rel=0.03)
    # honest std within the 0.8-1.25 of the bound, the truth within 3 of them
    assert 0.8 <= he.std[0] / bound <= 1.25
    assert abs(fit.theta[0] - c) < 3 * he.std[0]
    # the old fixed 10 s windows (each its own start) are far from the bound
    set_intensity(prob, KAPPA_GRID[0])
    assert top.theta_std[0] > 20 * bound


def test_a_random_walk_torque_makes_the_intensity_significant_and_the_errors_honest():
    rng = np.random.default_rng(3)
    tt = np.arange(0.0, 200.0, TORQUE_DT)
    # an unmodelled torque that walks the rate: white at 0.05 s, 2e-6 N m per sqrt(Hz)
    # (the rate wanders by 4e-5 rad/s per sqrt(s), 3e-4 rad/s over the run)
    kick = rng.normal(0.0, 2e-6 / np.sqrt(TORQUE_DT), tt.size)
    c = 2e-4
    prob, model, S = _problem([_coast(1.2, c, 200.0, 11, kick)])
    top = prob.fit(model.p0, S, np.zeros(1), name="top")
    fit = estimate_process_noise(prob, model.p0, S, top.theta, delta0=top.delta, start=top)
    pn = fit.extra["process_noise"]
    assert pn["significant"] and pn["kappa"] > KAPPA_GRID[-1], pn
    assert np.isfinite(pn["horizon_s"]) and pn["horizon_s"] > 0
    # a real torque: above what the integrator and the noise over the log explain
    floor = intensity_floor(prob, fit)
    assert floor < pn["kappa"]
    floored = above_floor(prob, fit, 1, (model.p0, S, None, None), floor).extra["process_noise"]
    assert floored["significant"] and floored["p"] < 1e-16, floored
    he = honest_errors(prob, fit, 1)
    # the errors widen beyond the bound of a correct model, and cover the truth
    assert he.std[0] > 2 * he.crlb[0]
    assert abs(fit.theta[0] - c) < 3 * he.std[0]


def test_residuals_come_back_per_segment_in_time_order():
    log = _coast(1.0, 1e-4, 40.0, 5)
    prob, model, S = _problem([log])
    fit = prob.fit(model.p0, S, np.zeros(1), name="fit")
    res = normalised_residuals(prob, fit)
    assert len(res) == 1
    rows = res[0].rows
    assert np.all(np.diff(rows) > 0) and rows[0] == 0 and rows[-1] == len(log.data) - 1
    assert np.all(np.diff(res[0].t) > 0)
    # noise units: the residual's spread is about one
    assert 0.7 < float(np.std(res[0].r)) < 1.3


def test_a_window_longer_than_every_segment_is_as_long_as_the_longest_segment():
    # two logs of 30 and 20 s: a 1e6 s window cuts each into one window, and the window set
    # holds no more rows than the longest (it padded every window to 1e7 rows and hung)
    logs = [_coast(2.0, 1e-4, 30.0, 1), _coast(2.0, 1e-4, 20.0, 2)]
    datas = [replay_data(ROTOR, lg) for lg in logs]
    for linked in (False, True):
        ws = make_windows(datas, window_s=1e6, linked=linked)
        assert ws.u.shape[:2] == (2, 300), ws.u.shape


def test_a_fit_from_the_last_answer_reuses_its_jacobian_and_finds_the_same_fit():
    prob, model, S = _problem([_coast(1.2, 2e-4, 30.0, 5)])
    set_intensity(prob, KAPPA_GRID[1])
    prob.reuse_last = True
    first = prob.fit(model.p0, S, np.zeros(1), name="first")
    # kept at the answer: the next fit's start ([theta, unused slots, vec(delta)])
    at = prob._last[0][0]
    assert at[0] == first.theta[0] and np.array_equal(at[-first.delta.size :],
                                                      first.delta.ravel(order="F"))  # fmt: skip
    set_intensity(prob, KAPPA_GRID[3])  # the descent's next intensity, from that answer
    kept = prob.fit(model.p0, S, first.theta, delta0=first.delta, name="kept")
    prob.reuse_last = False
    prob.forget_last()
    fresh = prob.fit(model.p0, S, first.theta, delta0=first.delta, name="fresh")
    # the start's Jacobian is the same numbers whether kept or evaluated again (the first
    # iterate's at most an ulp of the start away): the same fit to round-off
    assert kept.theta[0] == pytest.approx(fresh.theta[0], rel=1e-9)
    assert np.allclose(kept.delta, fresh.delta, rtol=1e-9, atol=1e-12)
    assert kept.rss == pytest.approx(fresh.rss, rel=1e-9)
    # the descent keeps nothing once done (a Jacobian is 100s of MB on an hour of samples)
    estimate_process_noise(prob, model.p0, S, first.theta, delta0=first.delta,
                           measurement=False)  # fmt: skip
    assert prob._last is None and not prob.reuse_last
