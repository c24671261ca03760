"""A penalised fit started at its optimum (the horizon's final fit) is taken as it is.

Reference: IPOPT's optimum of the same problem from a start a tenth of a std off, to the
optimiser's tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_process_noise import _coast, _problem

from airbearing.analysis.shooting.process_noise import KAPPA_GRID, set_intensity

C = 2e-4  # N m s, the coast-down's viscous friction (the free fit lands near it)


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
