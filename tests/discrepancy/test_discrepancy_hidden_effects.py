"""The discrepancy workflow names effects hidden in simulated logs (analysis/discrepancy.py).

Oracle: recovery (STYLE.md 4). Each log is simulated with an effect switched on in
the truth only (``scenarios.free_oscillation`` / ``scenarios.slew`` with
``effects=``); the workflow gets the nominal testbed and the log. Acceptance
(issue 7): the effect is named, its value is within 20 % (vector effects: the
norm of the error within 20 % of the norm of the truth) and the gap shrinks to
within 1.5 times the noise floor estimated from the data.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from airbearing.analysis.discrepancy.candidates import candidates_for
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.errors import InputError
from airbearing.io.log import read_log
from airbearing.io.testbed import Field, Sensors, load_testbed
from airbearing.models.effects import REGISTRY, WHEEL_EFFECTS

W0 = (0.3676, 0.1265, -1.4835)  # seed-004 initial rate (public example platform_viscous)
Q0 = (0.99458, 0.024955, -0.014973, 0.099819)
SLIDERS = (0.003, -0.002, 0.004)
PLATFORM_S = 24.0  # s of free oscillation: 4 windows of 6 s

PLATFORM = load_testbed("platform-3dof")
# a tilted cage field separates a residual dipole from a CM offset (FORMATS.md torques:
# m dr x g and m_res x b are parallel only when b is parallel to g)
TILTED = PLATFORM.replace(field=Field(lab=(4e-4, 0.0, 4.5e-4)))
_CMG = load_testbed("cmg-yaw")
# gyro noise of the public CMG examples (5e-4 rad/s), no low-pass
CMG = _CMG.replace(sensors=Sensors(rate=_CMG.sensors.rate, gyro_noise=5e-4, lowpass=1.0))

# effect -> (testbed, hidden value). Values are realistic and visible above the noise:
# viscous 6e-6 N m s is the public example's (a quarter of seed 000's residual torque at
# 1.5 rad/s); cm offsets of a few um are the balancing accuracy of seed 004; the inertia
# error of the CMG story is seed 001's 0.00323 / 0.00283 - 1 = 0.14.
HIDDEN = {
    "inertia_error": (CMG, 0.00323 / 0.00283 - 1),
    "viscous_friction": (PLATFORM, 6e-6),
    "coulomb_friction": (PLATFORM, 1e-5),
    "aero_drag": (PLATFORM, 5e-6),
    "spring_torque": (CMG, 2e-5),  # dof = 1 only
    "yaw_imbalance": (CMG, (2e-5, -1e-5)),  # dof = 1 only; as large as the spring's torque
    "cm_offset_error": (PLATFORM, (3e-6, -2e-6, 4e-6)),  # dof = 3 only
    "residual_dipole": (TILTED, (0.05, -0.08, 0.03)),
    "gyro_bias": (PLATFORM, 2e-3),  # dof 3: the attitude sensor makes a bias observable
    "sensor_lag": (PLATFORM, 0.05),
    "gimbal_deadzone": (CMG, 0.02),  # cmg only
}


def _log(tb, effects, seed):
    if tb.kind == "cmg":
        return slew(tb, effects=effects, seed=seed).log
    return free_oscillation(
        tb,
        initial_rate=W0,
        q0=Q0,
        sliders=SLIDERS,
        effects=effects,
        seed=seed,
        attitude_noise=1e-3,
        duration=PLATFORM_S,
    ).log


def _rel_error(found, truth) -> float:
    f, t = np.atleast_1d(found), np.atleast_1d(truth)
    return float(np.linalg.norm(f - t) / np.linalg.norm(t))


def test_every_registered_effect_has_a_hidden_effect_case():
    # the wheel_* effects act on reaction wheels only: their cases are in
    # tests/wheels/test_wheel_discrepancy.py
    assert set(HIDDEN) == set(REGISTRY) - set(WHEEL_EFFECTS)
    for name, (tb, _) in HIDDEN.items():
        # each is tested on a testbed kind where it can act (effects.applicable_effects)
        assert name in [c.name for c in candidates_for(tb)]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(HIDDEN), ids=list(HIDDEN))
def test_hidden_effect_is_named(name):
    tb, value = HIDDEN[name]
    log = _log(tb, {name: value}, seed=11)
    d = discrepancy(tb, log)
    assert name in d.effects, d.verdict
    assert len(d.effects) == 1, d.verdict
    assert _rel_error(d.effects[name], value) < 0.2
    # one value stays one value: its per-axis form (dof 3) costs two more parameters
    assert np.ndim(d.effects[name]) == np.ndim(value), d.verdict
    assert d.gap_before > 1.1 * d.noise_floor  # the effect was visible above the noise
    assert d.gap_after < 1.5 * d.noise_floor
    # the augmented testbed carries the named effect
    assert name in d.augmented_testbed.effects


@pytest.mark.slow
def test_two_hidden_effects_are_both_found():
    effects = {"viscous_friction": 6e-6, "cm_offset_error": (3e-6, -2e-6, 4e-6)}
    d = discrepancy(PLATFORM, _log(PLATFORM, effects, seed=12))
    assert set(d.effects) == set(effects), d.verdict
    for name, value in effects.items():
        assert _rel_error(d.effects[name], value) < 0.2
    assert d.gap_after < 1.5 * d.noise_floor


@pytest.mark.slow
def test_per_axis_friction_is_named_per_axis():
    # FORMATS.md: a list of three is one value per body axis. Spin-axis friction a fifth of
    # the tilt axes' (an air film is not isotropic); the one-value form cannot explain it
    value = (2e-5, 2e-5, 4e-6)
    d = discrepancy(PLATFORM, _log(PLATFORM, {"viscous_friction": value}, seed=14))
    assert set(d.effects) == {"viscous_friction"}, d.verdict
    assert len(d.effects["viscous_friction"]) == 3
    assert _rel_error(d.effects["viscous_friction"], value) < 0.2
    assert d.gap_after < 1.5 * d.noise_floor
    best = d.candidates[0]
    assert best.label == "viscous_friction (per axis)" and best.row()["per_axis"]


@pytest.mark.slow
def test_cm_offset_and_dipole_under_a_vertical_field_are_confounded():
    d = discrepancy(PLATFORM, _log(PLATFORM, {"cm_offset_error": (3e-6, -2e-6, 4e-6)}, seed=13))
    # FORMATS.md torques: mass dr x g_body = m_res x b_body when b || g: one and the same
    pair = {"cm_offset_error", "residual_dipole"}
    assert any(set(p) == pair for p in d.confounded)
    text = " ".join(d.experiments.values())
    assert "field" in text


# nothing hidden: the issue asks for "no missing effect" in at least 9 of 10 seeds
NULL_SEEDS = [(CMG, s) for s in range(100, 105)] + [(PLATFORM, s) for s in range(200, 205)]


@pytest.mark.slow
def test_nothing_hidden_gives_no_missing_effect():
    named = []
    for tb, seed in NULL_SEEDS:
        d = discrepancy(tb, _log(tb, {}, seed), max_effects=1)
        named.append(d.no_missing_effect)
    assert sum(named) >= 9, named


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
        assert _rel_error(d.effects[name], value) < 0.2


def test_bad_options():
    log = _log(CMG, {}, seed=1)
    with pytest.raises(InputError, match="unknown effect"):
        discrepancy(CMG, log, only=["friction"])
    with pytest.raises(InputError, match="cannot act"):
        discrepancy(CMG, log, only=["cm_offset_error"])
    with pytest.raises(InputError, match="max_effects=-1"):
        discrepancy(CMG, log, max_effects=-1)
