"""Corrections of nominal effects: a testbed's own ``[effects]`` value is fitted too.

A lab's testbed file carries last year's friction; ``discrepancy`` must be able to say
"your viscous_friction is 2e-5, not 2e-7". The nominal value stays in the Model and the
fit's ``theta`` is the correction, so the significance tests are of the correction and
the value reported (and written to the augmented testbed) is the total. Also here: the
words of a candidate pinned at either end of its range, and a spring's range (it cannot
push away from rest).

Oracle: a simulated coast-down of a motion-capture yaw rig (dof 1, no gyro, 1 mrad
noise) with viscous friction 2e-5 N m s, 100 times the nominal 2e-7.
"""

from __future__ import annotations

import numpy as np
import pytest
from judging import judged

import airbearing as ab
from airbearing.analysis.discrepancy.candidates import (
    PHYSICAL_RANGE,
    Candidate,
    candidates_for,
)
from airbearing.errors import InputError

TRUTH = 2e-5  # N m s
OLD = 2e-7  # N m s, the nominal of the testbed file (100 x too small)
RIG = {
    "kind": "platform",
    "name": "t",
    "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
    "sensors": {"rate": 10.0, "gyro": False, "attitude_noise": 0.001},
}


def _rig(effects=None):
    return ab.testbed_from_dict({**RIG, "effects": dict(effects or {})})


@pytest.fixture(scope="module")
def logs():
    # 60 s from 3 rad/s: the friction slows the spin by 2.4 %, a torque 100 x the
    # nominal's; two noise seeds, fitted jointly (one effect set) and each alone
    return [
        ab.spindown(_rig(), initial_rate=3.0, duration=60.0, seed=s,
                    effects={"viscous_friction": TRUTH}).log
        for s in (0, 1)
    ]  # fmt: skip


@pytest.fixture(scope="module")
def found(logs):
    return ab.discrepancy(_rig({"viscous_friction": OLD}), logs)


@pytest.mark.slow
def test_a_wrong_nominal_is_corrected_and_nothing_else_is_named(found):
    assert set(found.effects) == {"viscous_friction"}, found.verdict
    value, std = found.effects["viscous_friction"], found.effect_std["viscous_friction"]
    # the total, not the correction, within 3 honest standard errors of the truth
    assert abs(value - TRUTH) < 3 * std, found.verdict
    assert std < 0.01 * TRUTH, found.verdict  # a measurement, not a guess
    assert "viscous_friction = " in found.verdict and "(nominal 2e-07)" in found.verdict
    assert found.verdict.startswith("corrected effect:"), found.verdict
    # the augmented testbed (what --write-testbed writes) carries the total
    assert found.augmented_testbed.effects["viscous_friction"] == pytest.approx(value)
    doc = found.to_json()
    assert doc["effects"][0]["value"] == pytest.approx(value)
    row = next(r for r in doc["rounds"][0] if r["name"] == "viscous_friction")
    assert row["nominal"] == pytest.approx(OLD) and row["value"] > 50 * OLD


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_the_runs_alone_agree_on_the_total(found):
    assert len(found.per_log) == 2
    for f in found.per_log:
        v, sd = f.effects["viscous_friction"], f.std["viscous_friction"]
        assert abs(v - TRUTH) < 3 * sd, (f.log, v, sd)
    (agree,) = found.consistency
    assert agree.consistent, found.verdict


def test_only_a_nominal_effect_fits_its_correction(logs):
    d = ab.discrepancy(_rig({"viscous_friction": OLD}), logs[:1], only=["viscous_friction"])
    assert set(d.effects) == {"viscous_friction"}, d.verdict
    assert abs(d.effects["viscous_friction"] - TRUTH) < 3 * d.effect_std["viscous_friction"]
    (r,) = d.rounds[0]
    assert r.candidate.correction and r.nominal == OLD
    # theta is the correction: the total less the nominal
    assert r.theta[-1] == pytest.approx(r.value - OLD)


def test_a_right_nominal_leaves_nothing_to_name(logs):
    d = ab.discrepancy(_rig({"viscous_friction": TRUTH}), logs)
    assert d.effects == {} and not d.adequacy.structure_remains, d.verdict
    (r,) = [r for r in d.rounds[0] if r.name == "viscous_friction"]
    # the correction is what the tests judge: not significant, and near zero (the nominal
    # lies inside the range: no bound pins it)
    assert not r.significant and r.status != "at its physical bound", (r.status, r.reason)
    assert abs(r.theta[-1]) < 3 * r.std, (r.value, r.std)


# ----------------------------------------------------------------------------
# the candidates


def _names(cands):
    return [(c.name, c.per_axis, c.nominal) for c in cands]


def test_a_nominal_effect_is_a_correction_with_the_range_of_its_total():
    (c,) = candidates_for(_rig({"viscous_friction": OLD}), only=["viscous_friction"])
    assert c.correction and c.nominal == (OLD,) and c.label == "viscous_friction"
    lo, hi = PHYSICAL_RANGE["viscous_friction"]
    assert c.lower == (lo - OLD,) and c.upper == (hi - OLD,)
    assert c.value(np.array([1e-5])) == pytest.approx(1e-5 + OLD)  # the total
    assert c.spread(np.array([1e-9])) == 1e-9  # an error: no nominal added
    new = next(c for c in candidates_for(_rig()) if c.name == "viscous_friction")
    assert new.nominal is None and new.value(np.array([1e-5])) == 1e-5


def test_on_dof_3_one_value_only_when_every_axis_has_the_same_nominal():
    tb = ab.load_testbed("platform-3dof")
    same = candidates_for(tb.with_effects({"aero_drag": 1e-6}), only=["aero_drag"])
    assert _names(same) == [("aero_drag", False, (1e-6,)), ("aero_drag", True, (1e-6,) * 3)]
    axes = (1e-6, 2e-6, 3e-6)
    differ = candidates_for(tb.with_effects({"aero_drag": axes}), only=["aero_drag"])
    assert _names(differ) == [("aero_drag", True, axes)]


def test_a_lag_or_a_dead_zone_is_not_corrected_and_only_says_why():
    tb = ab.load_testbed("cmg-yaw").with_effects({"sensor_lag": 0.05})
    assert "sensor_lag" not in {c.name for c in candidates_for(tb)}
    with pytest.raises(InputError, match="only='sensor_lag': already in the .effects."):
        candidates_for(tb, only=["sensor_lag"])


def test_a_spring_cannot_push_away_from_rest():
    assert PHYSICAL_RANGE["spring_torque"][0] == 0.0
    (c,) = candidates_for(ab.load_testbed("cmg-yaw"), only=["spring_torque"])
    assert c.lower == (0.0,)


# ----------------------------------------------------------------------------
# the words of a pinned candidate


def _judged(cand, theta):
    return judged(cand, theta, 1e-3 * max(abs(theta), 1e-9))


INERTIA = Candidate(name="inertia_error", params=("inertia_error",), tie=np.ones((1, 1)),
                    lower=(-0.9,), upper=(9.0,))  # fmt: skip
FRICTION = Candidate(name="viscous_friction", params=("viscous_friction",), tie=np.ones((1, 1)),
                     lower=(-OLD,), upper=(1.0 - OLD,), nominal=(OLD,))  # fmt: skip


@pytest.mark.parametrize(
    "cand, theta, words",
    [
        (INERTIA, -0.9, "pinned at its smallest physical value -0.9: the fit wants less"),
        (INERTIA, 9.0, "pinned at its largest physical value 9: the fit wants more"),
        # a correction speaks of its total: the friction at 0, not the correction at -2e-7
        (FRICTION, -OLD, "pinned at its physical bound 0: the fit wants a value at or beyond"),
        (FRICTION, 1.0 - OLD, "pinned at its largest physical value 1: the fit wants more"),
    ],
)
def test_a_pinned_candidate_says_which_end_of_its_range(cand, theta, words):
    r = _judged(cand, theta)
    assert r.status == "at its physical bound" and words in r.reason, r.reason
    assert not r.nameable
    if cand.correction and theta < 0:
        assert "less of this effect than its nominal 2e-07" in r.reason
