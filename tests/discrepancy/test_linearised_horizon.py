"""The horizon's shortcuts: likelihoods from a fit's linearisation instead of new fits.

The process-noise intensity's fits along the grid come from one IPOPT fit's Gauss-Newton
linearisation when it holds there (:class:`process_noise.Linearisation`), and the coloured
measurement noise's trial likelihoods from sums over rows grouped by sample interval
(:class:`measurement_noise._Linearised`). References: an IPOPT fit at the same intensity,
and the likelihood whitened row by row (itself checked against the AR(1) covariance in
``test_measurement_noise.py``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from rigs import ROTOR, rotor_viscous_problem

from airbearing.analysis.shooting.measurement_noise import _Linearised
from airbearing.analysis.shooting.process_noise import (
    KAPPA_GRID,
    Linearisation,
    loglik,
    set_intensity,
)
from airbearing.io.log import Log

J_ZZ = 0.05  # kg m^2, the rig's yaw inertia (rigs.MOCAP_RIG_TOML)
C_TRUE = 2e-4  # N m s, viscous friction
RATE_HZ = 10.0


def _problem(seed: int, phi: float = 0.0, seconds: float = 60.0):
    """A viscous coast-down (closed form) with AR(1) yaw noise, on linked 10 s pieces."""
    t = np.arange(0.0, seconds, 1.0 / RATE_HZ)
    a = C_TRUE / J_ZZ
    yaw = 1.2 * (1 - np.exp(-a * t)) / a
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, 1.5e-3, t.size)
    for i in range(1, t.size):  # AR(1) of marginal level 1.5e-3 rad
        e[i] = phi * e[i - 1] + np.sqrt(1 - phi**2) * e[i]
    log = Log(pd.DataFrame({"t": t, "yaw": yaw + e}), source=f"c{seed}.csv", testbed=ROTOR)
    return rotor_viscous_problem([log])


def test_grouped_noise_likelihood_is_the_row_by_row_one():
    prob, model, S = _problem(1, phi=0.9)
    # a hole: one usable row taken out (an outlier), so a second interval of 2 samples
    # (in the problem's own usable rows: the windows' arrays are views of the data
    # vector the problems share, read-only)
    weight = prob.windows.weight.copy()
    weight[2, 5] = 0.0
    prob.usable = weight.reshape(-1)[prob.sample] > 0
    set_intensity(prob, KAPPA_GRID[0])
    top = prob.fit(model.p0, S, np.zeros(1), name="top")
    lin = _Linearised(prob, top, 1)
    dt = 1.0 / RATE_HZ
    for ar in ({}, {"yaw": (0.9, 0.5)}, {"yaw": (-0.4, 2.0)}, {"yaw": (0.0, 1.3)}):
        # the same sums in another order: equal to round-off of ~600 rows' squares
        assert lin.loglik(ar, dt) == pytest.approx(lin.exact(ar, dt), rel=1e-12, abs=1e-8)


def test_linearised_intensity_fit_is_the_ipopt_fit():
    prob, model, S = _problem(2)
    set_intensity(prob, KAPPA_GRID[0])
    top = prob.fit(model.p0, S, np.zeros(1), name="top")
    bounds = (model.p0.copy(), S, None, None)
    lin = Linearisation.of(prob, top, 1, bounds)
    for kappa in (1e-2, 1e-6):
        point, ll = lin.at(kappa)
        set_intensity(prob, kappa)
        fit = prob.fit(model.p0, S, top.theta, delta0=top.delta, name="at kappa")
        # the effect where IPOPT puts it, to a hundredth of its error (IPOPT itself stops
        # at a scaled gradient of about 1e-5 here), the objective and the likelihood to
        # 1e-3 (the linearisation's stop: a further step would gain less than 1e-4)
        assert abs(point.theta[0] - fit.theta[0]) < 0.01 * fit.theta_std[0]
        assert point.rss == pytest.approx(fit.rss, abs=1e-3)
        assert ll == pytest.approx(loglik(prob, fit, 1), abs=1e-3)
    # an effect the linearisation would take out of its bounds is IPOPT's
    below = (model.p0.copy(), S, np.array([0.0]), np.array([0.5 * top.theta[0]]))
    assert Linearisation.of(prob, top, 1, below).at(1e-2) is None
