"""Coloured measurement noise: the AR(1) whitening, its estimate, and the errors it gives.

Reference values are derived here: the AR(1) covariance ``s^2 / (1 - phi^2) phi^|i-j|``
(the whitening must invert it exactly, holes in the series included), and the spread of
the estimate over repeated noise draws (the reported std must match it).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from rigs import ROTOR, rotor_viscous_problem

from airbearing.analysis.shooting.errors import honest_errors
from airbearing.analysis.shooting.measurement_noise import (
    MeasurementNoise,
    estimate_measurement_noise,
    set_measurement_noise,
    whitening,
)
from airbearing.analysis.shooting.process_noise import estimate_process_noise
from airbearing.io.log import Log

J_ZZ = 0.05  # kg m^2, the rig's yaw inertia (rigs.MOCAP_RIG_TOML)
SIGMA = 1.5e-3  # rad, marginal attitude noise
RATE_HZ = 10.0
C_TRUE = 2e-4  # N m s, viscous friction


def _ar1(rng, n, phi, sigma):
    x = np.empty(n)
    x[0] = rng.normal(0.0, sigma)
    e = rng.normal(0.0, sigma * np.sqrt(1 - phi**2), n)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + e[i]
    return x


def _coast(seed, phi, seconds=120.0, w0=1.2):
    """A viscous coast-down (closed form) with AR(1) yaw noise of coefficient ``phi``."""
    t = np.arange(0.0, seconds, 1.0 / RATE_HZ)
    a = C_TRUE / J_ZZ
    yaw = w0 * (1 - np.exp(-a * t)) / a
    rng = np.random.default_rng(seed)
    noise = _ar1(rng, t.size, phi, SIGMA) if phi else rng.normal(0.0, SIGMA, t.size)
    df = pd.DataFrame({"t": t, "yaw": yaw + noise})
    return Log(df, source=f"coast{seed}.csv", testbed=ROTOR)


def test_whitening_inverts_the_ar1_covariance_across_pieces_and_holes():
    prob, _, _ = rotor_viscous_problem([_coast(1, 0.0, seconds=30.0)])
    # a hole: one usable row taken out of the second piece (an outlier)
    # (in the problem's own usable rows: the windows' arrays are views of the data
    # vector the problems share, read-only)
    weight = prob.windows.weight.copy()
    weight[1, 7] = 0.0
    prob.usable = weight.reshape(-1)[prob.sample] > 0
    phi, s, dt = 0.9, 1.7, 0.1
    P, logdet = whitening(prob, {"yaw": (phi, s)}, dt)
    from airbearing.analysis.shooting.errors import _segment_order

    (_, _, idx, t) = _segment_order(prob)[0]
    L = prob.windows.length
    rows = (idx // L) * prob.n_win_res + idx % L
    lag = np.abs(t[:, None] - t[None, :]) / dt
    Sigma = s**2 / (1 - phi**2) * phi**lag
    Pb = P[rows][:, rows].toarray()
    # P Sigma P' = I on the usable rows, in time order over the pieces and the hole
    assert np.allclose(Pb @ Sigma @ Pb.T, np.eye(rows.size), atol=1e-9)
    # lower triangular in the residual's order (an unwhitening is one triangular solve)
    assert abs(P - __import__("scipy.sparse", fromlist=["tril"]).tril(P)).sum() == 0
    # log det P = -1/2 log det Sigma on the usable rows; the other rows are identity
    assert logdet == pytest.approx(-0.5 * np.linalg.slogdet(Sigma)[1], rel=1e-9)


def test_ar1_noise_is_found_and_white_noise_is_left_white():
    prob, model, S = rotor_viscous_problem([_coast(2, 0.9)])
    top = prob.fit(model.p0, S, np.zeros(1), name="top")
    noise = estimate_measurement_noise(prob, top, 1)
    assert noise is not None
    phi, s = noise.ar["yaw"]
    # REML on nearly free 10 s pieces: within 0.03 of the truth (1200 samples: the
    # coefficient's own standard error is sqrt((1 - phi^2) / n) = 0.013)
    assert phi == pytest.approx(0.9, abs=0.03)
    # the innovation's level in units of the difference floor: the marginal level
    # s / sqrt(1 - phi^2) times the floor is the noise's 1.5e-3 rad within 15 %
    marginal = s / np.sqrt(1 - phi**2) * prob.sigma_att
    assert marginal == pytest.approx(SIGMA, rel=0.15)
    assert noise.p["yaw"] < 1e-6

    prob_w, model_w, S_w = rotor_viscous_problem([_coast(3, 0.0)])
    top_w = prob_w.fit(model_w.p0, S_w, np.zeros(1), name="top")
    assert estimate_measurement_noise(prob_w, top_w, 1) is None


def test_gap_and_noise_rms_are_of_the_raw_residual():
    prob, model, S = rotor_viscous_problem([_coast(4, 0.9, seconds=60.0)])
    fit = prob.fit(model.p0, S, np.zeros(1), name="white")
    gap = fit.gap
    set_measurement_noise(prob, MeasurementNoise({"yaw": (0.9, 0.5)}, 0.1, {}, {}))
    fit2 = prob.fit(model.p0, S, fit.theta, delta0=fit.delta, name="whitened")
    # the whitened residual is not the gap's: the gap stays the RMS of the yaw error
    assert fit2.gap == pytest.approx(gap, rel=0.05)
    assert prob.noise_rms(fit2.extra["r"])["yaw"] == pytest.approx(fit2.gap, rel=1e-9)


@pytest.mark.slow
def test_errors_under_ar1_noise_match_the_spread_over_repeated_runs():
    """The issue's case (b) in small: AR(1) 0.95 noise, one 120 s coast-down per run.

    White-noise errors are several times too small here; with the noise model the reported
    std must match the real spread of the estimates over 8 noise draws (within 0.5-2x, the
    issue's band: with 8 draws the sample std itself is uncertain by 25 %)."""
    values, stds = [], []
    for seed in range(8):
        prob, model, S = rotor_viscous_problem([_coast(100 + seed, 0.95)])
        top = prob.fit(model.p0, S, np.zeros(1), name="top")
        fit = estimate_process_noise(prob, model.p0, S, top.theta, delta0=top.delta, start=top)
        assert fit.extra["measurement_noise"] is not None
        he = honest_errors(prob, fit, 1)
        values.append(fit.theta[0])
        stds.append(he.std[0])
    values, stds = np.array(values), np.array(stds)
    spread = float(np.sqrt(np.mean((values - C_TRUE) ** 2)))
    assert 0.5 <= float(np.median(stds)) / spread <= 2.0
    assert np.all(np.abs(values - C_TRUE) < 3.5 * stds)
