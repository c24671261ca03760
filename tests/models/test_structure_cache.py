"""The structure key (models/structure_cache.py) tells apart what lays out ``p`` differently.

Oracle: a Model's parameter vector follows its effects in their order
(``Model.p_names``), so two Models with the same effects in another order are two
structures; the compiled functions cached by the key of one must never serve the other.
"""

from __future__ import annotations

import numpy as np
import pytest
from rigs import ROTOR

from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.simulation.scenarios import spindown
from airbearing.models.structure_cache import structure_key

EFFECTS = {"coulomb_friction": 0.0, "aero_drag": 0.0, "viscous_friction": 0.0}


def _two_orders():
    # the testbed's own effects come first in p: viscous first here, by name in the other
    first = model_for(ROTOR.with_effects({"viscous_friction": 0.0}), EFFECTS)
    other = model_for(ROTOR, EFFECTS)
    assert set(first.p_names) == set(other.p_names) and first.p_names != other.p_names
    return first, other


def test_effects_in_another_order_are_another_structure():
    first, other = _two_orders()
    assert structure_key(first) != structure_key(other)
    assert structure_key(ROTOR.with_effects({"aero_drag": 1.0, "coulomb_friction": 2.0})) != (
        structure_key(ROTOR.with_effects({"coulomb_friction": 2.0, "aero_drag": 1.0}))
    )
    # values alone never decide the structure
    again = model_for(ROTOR, {**EFFECTS, "aero_drag": 3e-6})
    assert structure_key(again) == structure_key(other) and again.p_names == other.p_names


def test_a_fit_after_another_parameter_order_reads_its_own_slots():
    # one process fits the same log on both Models: the second once ran on the first's
    # compiled window functions (same key) and read its coulomb slot as aero_drag's
    truth = 1e-5  # N m
    log = spindown(ROTOR, initial_rate=1.5, duration=60.0, effects={"coulomb_friction": truth},
                   seed=1).log  # fmt: skip
    datas, windows, floor = prepare(ROTOR, [log])
    found, std = [], []
    for model in _two_orders():
        problem = problem_for(model, datas, windows, floor, jit=False)
        S = np.zeros((model.n_p, 1))
        S[model.index("coulomb_friction", "p")[0], 0] = 1.0
        fit = problem.fit(model.p0, S, np.zeros(1), name="coulomb friction alone")
        found.append(float(fit.theta[0]))
        std.append(float(fit.theta_std[0]))
    # the same data and the same physics by name: the same value up to round-off of the
    # summation order (the wrong slot read aero_drag's physics: 4.7e-6 on this log)
    assert found[1] == pytest.approx(found[0], rel=1e-6)
    # 60 s at 10 Hz with 1 mrad yaw noise: standard error 5e-7 N m; within 4 of them
    assert abs(found[0] - truth) < 4 * std[0]
