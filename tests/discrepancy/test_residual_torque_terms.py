"""The residual torque's regressors, shared by a round's candidates.

Oracle: physics. A per-axis viscous friction adds the torque ``-b_i w_i`` about each body
axis (FORMATS.md), so its regressor in ``J w'`` is ``-w_i`` on axis ``i`` and 0 on the
others, whatever the parameters the Model's acceleration is taken at; the one-value form
(one ``b`` on every axis) is their sum. The terms are evaluated once per point and shared:
each candidate's columns must be what it gets alone, and a second point must not be served
the first's.
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.discrepancy.candidates import (
    candidates_for,
    residual_torque,
    smoothed,
    universal_effects,
)
from airbearing.analysis.discrepancy.replay import model_for, prepare
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.io.testbed import load_testbed

W0 = (0.3676, 0.1265, -1.4835)  # seed-004 initial rate (as test_confounding.py)
Q0 = (0.99458, 0.024955, -0.014973, 0.099819)


def _setup():
    tb = load_testbed("platform-3dof")
    log = free_oscillation(
        tb, initial_rate=W0, q0=Q0, sliders=(0.003, -0.002, 0.004),
        effects={"viscous_friction": 2e-5}, seed=13, attitude_noise=1e-3, duration=6.0,
    ).log  # fmt: skip
    datas, _, _ = prepare(tb, [log])
    cands = candidates_for(tb, datas)
    model = model_for(tb, universal_effects(tb, dict.fromkeys(c.name for c in cands if not c.lag)))

    def S_of(*cs):
        S = np.zeros((model.n_p, sum(c.k for c in cs)))
        i = 0
        for c in cs:
            S[model.index(list(c.params), "p"), i : i + c.k] = c.tie
            i += c.k
        return S

    return datas, cands, model, S_of


def test_viscous_friction_regressor_is_minus_the_rate_on_its_own_axis():
    datas, cands, model, S_of = _setup()
    per_axis = next(c for c in cands if c.name == "viscous_friction" and c.per_axis)
    one = next(c for c in cands if c.name == "viscous_friction" and not c.per_axis)
    w_s, _, ok = smoothed(datas[0])
    w = w_s[ok]
    # at the nominal parameters, then at a friction already in the Model (a later round)
    p1 = model.p0 + S_of(one) @ np.array([3e-5])
    for p in (model.p0, p1):
        _, phi = residual_torque(model, datas, p, S_of(per_axis))
        # -w, but the torque is taken with the body's inertia and the Model's acceleration
        # with the sliders' too: 1e-4 of the rate (the sliders' mm against the body)
        tol = 1e-4 * float(np.max(np.abs(w)))
        np.testing.assert_allclose(phi, -w[:, :, None] * np.eye(3)[None], rtol=0, atol=tol)
        _, phi1 = residual_torque(model, datas, p, S_of(one))
        np.testing.assert_allclose(phi1[:, :, 0], -w, rtol=0, atol=tol)


def test_candidates_share_the_terms_of_one_point_but_not_of_another():
    datas, cands, model, S_of = _setup()
    smooth = [c for c in cands if c.smooth and not c.lag]
    one = next(c for c in cands if c.name == "viscous_friction" and not c.per_axis)
    together = residual_torque(model, datas, model.p0, S_of(*smooth))[1]
    i = 0
    for c in smooth:
        alone = residual_torque(model, datas, model.p0, S_of(c))[1]
        # one product per entry for these ties (each derivative column times 1): equal to
        # rounding of a sum's order (1e-15 of the largest)
        scale = max(float(np.max(np.abs(alone))), 1e-300)
        np.testing.assert_allclose(together[:, :, i : i + c.k], alone, rtol=0, atol=1e-15 * scale)
        i += c.k
    # the residual torque itself moves with the parameters: a friction of 1e-3 N m s in
    # the Model adds about b w to J w' - J a (the inertias as above)
    tau0 = residual_torque(model, datas, model.p0, S_of(one))[0]
    tau1 = residual_torque(model, datas, model.p0 + S_of(one) @ np.array([1e-3]), S_of(one))[0]
    w_s, _, ok = smoothed(datas[0])
    w = w_s[ok]
    np.testing.assert_allclose(tau1 - tau0, 1e-3 * w, rtol=0, atol=1e-4 * 1e-3 * np.max(np.abs(w)))
