"""A free fit keeps the window Jacobian at its start for the bounded fit after it only up
to ``problem.KEEP_START_MAX_BYTES``; above it the bounded fit evaluates it again.

Reference: the same bounded fit with the start kept, to the bit (the window Jacobian is a
deterministic function of the point, the parameters and the data).
"""

from __future__ import annotations

import numpy as np
from test_process_noise import _coast, _problem

from airbearing.analysis.shooting import problem as problem_module
from airbearing.analysis.shooting.problem import ShootingProblem
from airbearing.analysis.shooting.process_noise import KAPPA_GRID, set_intensity

C = 2e-4  # N m s, the coast-down's viscous friction (the free fit lands near it)


def _bounded_fit(monkeypatch, limit):
    prob, model, S = _problem([_coast(1.2, C, 30.0, 5)])
    set_intensity(prob, KAPPA_GRID[2])
    monkeypatch.setattr(problem_module, "KEEP_START_MAX_BYTES", limit)
    kept = []
    linked_raw = ShootingProblem._linked_raw

    def spy(self, *args):
        out = linked_raw(self, *args)
        kept.append(self._start_kept is not None)
        return out

    monkeypatch.setattr(ShootingProblem, "_linked_raw", spy)
    # the free fit lands near C, outside the bound C / 2: the bounded fit follows
    fit = prob.fit(model.p0, S, np.zeros(1), lower=np.zeros(1), upper=np.full(1, C / 2))
    return fit, kept


def test_a_bounded_fit_is_the_same_to_the_bit_without_the_kept_start(monkeypatch):
    with_start, kept = _bounded_fit(monkeypatch, 2**40)
    assert kept[0]  # the free fit's start was kept
    without, kept = _bounded_fit(monkeypatch, 0)
    assert not any(kept)
    # at the bound (IPOPT relaxes its bounds by 1e-8 relative)
    assert abs(with_start.theta[0] - C / 2) < 1e-6 * C
    np.testing.assert_array_equal(without.theta, with_start.theta)
    np.testing.assert_array_equal(without.delta, with_start.delta)
    np.testing.assert_array_equal(without.theta_std, with_start.theta_std)
    assert without.rss == with_start.rss and without.iterations == with_start.iterations
