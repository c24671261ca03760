"""The process noise judged at the sub-steps the named effects need (:mod:`.horizon`): a
noise-free attitude whose named model is the truth shows no unexplained torque."""

from __future__ import annotations

import pytest

import airbearing as ab

TRUTH = {"aero_drag": 2e-5, "coulomb_friction": 3e-5}  # N m s^2, N m (hidden_cases_cli's)


@pytest.mark.slow
def test_an_exact_attitude_with_the_true_effects_named_leaves_no_process_noise():
    # seed 000's tabletop coasting down from 2 rad/s for 60 s, exact attitude: the horizon
    # (2 sub-steps, the nominal model's) found kappa 10, LR 158; refitted at the fitted
    # Coulomb friction's 32 sub-steps and tested again there, the intensity falls to the
    # bottom of the grid, and the errors are the bound's (std / bound 5-44 before)
    tb = ab.load_testbed("seed000-tabletop")
    run = ab.spindown(tb, initial_rate=2.0, duration=60.0, effects=TRUTH, attitude_noise=0.0)
    found = ab.discrepancy(tb, [run.log], only=list(TRUTH))
    doc = found.to_json()
    pn = doc["adequacy"]["process_noise"]
    assert not pn["significant"], (pn, found.verdict)
    assert not doc["adequacy"]["structure_remains"], found.verdict
    assert "unexplained torque is significant" not in found.verdict
    for e in doc["effects"]:
        truth = TRUTH[e["name"]]
        value, std = e["value"], e["std"]
        value = value if isinstance(value, list) else [value]
        std = std if isinstance(std, list) else [std]
        for v, s in zip(value, std, strict=True):
            assert abs(v - truth) < 1e-3 * truth, found.verdict
            assert abs(v - truth) < 4 * s, found.verdict  # the bound's errors cover it
        eff = e["efficiency"] if isinstance(e["efficiency"], list) else [e["efficiency"]]
        assert max(eff) < 3.0, found.verdict  # at the bound, not widened by a false noise
