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
