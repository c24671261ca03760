"""A bounded fit whose free fit leaves the bounds: the parameter held at the bound it
crossed is the interior-point fit's answer (the bound active, its multiplier of the right
sign), for fewer iterations.

Reference: the same problem solved by IPOPT with the bound (the interior-point path the
held fit replaces), to the optimiser's tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_process_noise import _coast, _problem

from airbearing.analysis.shooting.process_noise import KAPPA_GRID, set_intensity

C = 2e-4  # N m s, the coast-down's viscous friction (the free fit lands near it)


def _interior_point(prob, *args, **kw):
    """The bounded IPOPT fit: the held fit switched off on this problem."""
    prob._held_at_bound = lambda *a, **k: None
    try:
        return prob.fit(*args, **kw)
    finally:
        del prob._held_at_bound


@pytest.mark.parametrize("side", ["upper", "lower"])
def test_a_fit_beyond_its_bound_is_held_there_as_the_interior_point_fit_ends(side):
    prob, model, S = _problem([_coast(1.2, C, 30.0, 5)])
    set_intensity(prob, KAPPA_GRID[2])
    # a bound the free fit crosses: half the truth above, twice it below
    bounds = {"upper": np.array([C / 2])} if side == "upper" else {"lower": np.array([2 * C])}
    at = next(iter(bounds.values()))[0]
    held = prob.fit(model.p0, S, np.zeros(1) if side == "upper" else np.array([2 * C]),
                    name="held", **bounds)  # fmt: skip
    ref = _interior_point(prob, model.p0, S, np.zeros(1) if side == "upper" else
                          np.array([2 * C]), name="ref", **bounds)  # fmt: skip
    assert held.theta[0] == at  # exactly at the bound
    assert held.level == ref.level == "converged"
    # the interior point stops within its tolerance of the bound (1e-6 in variables scaled
    # so that a step of 1 moves the residual by ~1 sigma): a thousandth of a std is far
    # beyond it, and the states and the chi-square agree to the same order
    assert abs(ref.theta[0] - at) < 1e-3 * ref.theta_std[0]
    assert held.theta_std[0] == pytest.approx(ref.theta_std[0], rel=1e-4)
    assert held.rss == pytest.approx(ref.rss, rel=1e-6)
    assert np.allclose(held.delta, ref.delta, rtol=1e-4, atol=1e-3 * np.abs(ref.delta).max())
    # fewer IPOPT iterations than the barrier's walk to the bound
    assert held.iterations < ref.iterations


def test_a_fit_started_at_its_optimum_stops_there_without_iterating():
    prob, model, S = _problem([_coast(1.2, C, 30.0, 5)])
    set_intensity(prob, KAPPA_GRID[2])
    first = prob.fit(model.p0, S, np.zeros(1), name="first")
    sd = first.theta_std[0]
    prob.objective_stop = True  # as the horizon's final fit (IPOPT's objective stop)
    try:
        # 1e-5 std from the optimum: the gradient above IPOPT's tolerance (it would iterate),
        # the Gauss-Newton step's gain far below the objective stop's 1e-10 of the objective
        near = prob.fit(model.p0, S, first.theta + 1e-5 * sd, delta0=first.delta, name="near")
        # a tenth of a std off: not taken as it is
        off = prob.fit(model.p0, S, first.theta + 0.1 * sd, delta0=first.delta, name="off")
    finally:
        prob.objective_stop = False
    assert near.iterations == 0 and near.level == "converged"
    assert near.status == "Solved_To_Acceptable_Level"  # as IPOPT's objective stop says
    # the start itself (to the round-off of the column scaling and back)
    assert near.theta[0] == pytest.approx(first.theta[0] + 1e-5 * sd, rel=1e-12)
    assert off.iterations > 0
    # IPOPT's optimum from there is the first, to its tolerance (a step of 1 in the scaled
    # variables moves the residual by ~1 sigma: 1e-3 std is far beyond it)
    assert abs(off.theta[0] - first.theta[0]) < 1e-3 * sd
