"""The decade either side of the most likely intensity comes from ITS linearisation.

A friction the nominal three-axis Model lacks, far above the noise, puts the most likely
intensity at the top of the grid while the descent's last IPOPT fit sits at its bottom
(nearly one trajectory per piece), whose linearisation holds nowhere near the top: the
decade below the best is solved on the best's own Gauss-Newton linearisation instead of
by one more IPOPT fit. The whole descent (the discrepancy search's; ``replay`` ends it once
the likelihood has clearly peaked) on the replay's problem.
"""

from __future__ import annotations

import pytest
from rigs import jittered_platform

import airbearing as ab
from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.shooting.problem import ShootingProblem
from airbearing.analysis.shooting.process_noise import KAPPA_GRID, estimate_process_noise

PLATFORM = ab.load_testbed("platform-3dof")


@pytest.mark.slow  # a 25 s three-axis replay's whole descent: about 6 s
def test_the_decade_below_a_best_at_the_top_is_no_ipopt_fit(monkeypatch):
    log = jittered_platform(PLATFORM, 3, duration=25.0, effects={"viscous_friction": 3e-3})
    names = []
    fit = ShootingProblem.fit

    def counted(self, *args, **kwargs):
        names.append(kwargs.get("name", ""))
        return fit(self, *args, **kwargs)

    monkeypatch.setattr(ShootingProblem, "fit", counted)
    datas, windows, floor = prepare(PLATFORM, [log])
    model = model_for(PLATFORM)
    problem = problem_for(model, datas, windows, floor, theta_slots=0)
    start = problem.fit(model.p0)
    pn = estimate_process_noise(problem, model.p0, start=start).extra["process_noise"]
    best = pn["kappa"]
    assert best == KAPPA_GRID[0] and pn["significant"], pn
    # the descent reached the bottom of the grid by IPOPT fits (the linearisation of the
    # top does not hold that far down)
    assert pn["kappa_whole"] == KAPPA_GRID[-1], pn
    assert any(f"({KAPPA_GRID[-2]:g})" in n for n in names), names
    # the decade below the best was tried, and not by IPOPT
    below = best / 10.0
    assert below in pn["loglik"] and pn["loglik"][below] < pn["loglik"][best], pn
    assert not any(f"({below:g})" in n for n in names), names
