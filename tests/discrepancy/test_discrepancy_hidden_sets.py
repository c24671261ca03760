"""The discrepancy workflow on sets of hidden effects: two at once, one per axis, none,
and the public examples (analysis/discrepancy.py).

Oracle: recovery (STYLE.md 4), as in test_discrepancy_hidden_effects.py (one effect per
log; its logs and acceptance: tests/hidden_cases.py): the effects are named, each within
20 % (vector effects: norms), the gap within 1.5 times the noise floor; with nothing
hidden, no missing effect.
"""

from __future__ import annotations

import json

import pytest
from hidden_cases import CMG, PLATFORM, hidden_log, rel_error

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.io.log import read_log
from airbearing.io.testbed import load_testbed


@pytest.mark.slow
def test_two_hidden_effects_are_both_found():
    effects = {"viscous_friction": 6e-6, "cm_offset_error": (3e-6, -2e-6, 4e-6)}
    d = discrepancy(PLATFORM, hidden_log(PLATFORM, effects, seed=12))
    assert set(d.effects) == set(effects), d.verdict
    for name, value in effects.items():
        assert rel_error(d.effects[name], value) < 0.2
    assert d.gap_after < 1.5 * d.noise_floor


@pytest.mark.slow
def test_per_axis_friction_is_named_per_axis():
    # FORMATS.md: a list of three is one value per body axis. Spin-axis friction a fifth of
    # the tilt axes' (an air film is not isotropic); the one-value form cannot explain it
    value = (2e-5, 2e-5, 4e-6)
    d = discrepancy(PLATFORM, hidden_log(PLATFORM, {"viscous_friction": value}, seed=14))
    assert set(d.effects) == {"viscous_friction"}, d.verdict
    assert len(d.effects["viscous_friction"]) == 3
    assert rel_error(d.effects["viscous_friction"], value) < 0.2
    assert d.gap_after < 1.5 * d.noise_floor
    best = d.candidates[0]
    assert best.label == "viscous_friction (per axis)" and best.row()["per_axis"]


@pytest.mark.slow
def test_a_gyro_bias_of_either_sign_per_axis_is_named_per_axis():
    # a signed effect's one-value form is the axes' average, here zero: not significant,
    # so the per-axis form is tried whatever the one-value form's test says (a friction's
    # one value cannot cancel)
    value = (2e-3, -2e-3, 0.0)
    d = discrepancy(PLATFORM, hidden_log(PLATFORM, {"gyro_bias": value}, seed=15))
    assert set(d.effects) == {"gyro_bias"}, d.verdict
    assert len(d.effects["gyro_bias"]) == 3
    assert rel_error(d.effects["gyro_bias"], value) < 0.2


# nothing hidden: the issue asks for "no missing effect" in at least 9 of 10 seeds, i.e. a
# false-alarm rate of at most about 10 %. Six seeds with none allowed test that as well
# (scipy.stats.binom): a workflow naming a false effect in 30 % of logs passes 9-of-10 with
# probability 0.15 and 6-of-6 with 0.12; one at 5 % passes them with 0.91 and 0.74
NULL_SEEDS = [(CMG, s) for s in range(100, 103)] + [(PLATFORM, s) for s in range(200, 203)]


@pytest.mark.slow
def test_nothing_hidden_gives_no_missing_effect():
    named = []
    for tb, seed in NULL_SEEDS:
        d = discrepancy(tb, hidden_log(tb, {}, seed), max_effects=1)
        named.append(d.no_missing_effect)
    assert all(named), named


@pytest.mark.slow
@pytest.mark.parametrize("example", ["platform_viscous", "cmg_inertia", "cmg_none"])
def test_public_examples_are_named(example, example_case):
    # the public examples' cases, simulated by the package (tests/conftest.py), so no skip
    folder = example_case(example)
    tb = load_testbed(folder / "testbed.toml")
    d = discrepancy(tb, read_log(folder / "log.csv", tb))
    answer = json.loads((folder / "answer.json").read_text())["effects"]
    assert set(d.effects) == set(answer), d.verdict
    for name, value in answer.items():
        assert rel_error(d.effects[name], value) < 0.2
