"""What the discrepancy search cannot see on reaction-wheel logs is said, not hidden.

The search fits the table's outputs; the logged wheel speeds only start each window.

With torque-commanded wheels the body's outputs see a wheel's spin-axis inertia only
through ``J - Iw`` (a part in a thousand of the yaw inertia on ``rw-yaw``); the logged
wheel speeds, whose slope would show it, only start each window. A 10 % wheel inertia
error in a slew then leaves the body's rate as the nominal model predicts it, and "no
missing effect" alone would read as if the wheels were checked: the verdict must say that
these logs hardly show ``wheel_inertia_error`` and how to measure it. Likewise a wheel's
bearing friction while the wheel never reverses is one constant torque on the table, which
the table's rate cannot tell from a torque the model does not hold: the verdict says so,
with the experiment that separates them.
"""

import dataclasses
from types import SimpleNamespace

import airbearing as ab
from airbearing.analysis.discrepancy.judgement import _wheel_inertia_unseen
from airbearing.analysis.discrepancy.words import WHEEL_INERTIA_UNSEEN
from airbearing.io.testbed import load_testbed

WHEEL_INERTIA = 0.1  # a tenth: a wheel whose data-sheet inertia is 10 % off


def test_a_hidden_wheel_inertia_error_is_said_to_be_unseen_not_absent():
    tb = load_testbed("rw-yaw")
    # a 60 deg slew in 20 s: the wheel reaches tens of rad/s, four 5 s windows
    log = ab.slew(
        tb, angle_deg=60.0, duration=20.0, seed=5, effects={"wheel_inertia_error": WHEEL_INERTIA}
    ).log
    found = ab.discrepancy(tb, [log])
    assert "wheel_inertia_error" not in found.effects, str(found)
    assert "hardly show wheel_inertia_error" in found.verdict, found.verdict
    assert WHEEL_INERTIA_UNSEEN in found.verdict
    assert "known motor torque" in found.verdict


def _sel(names):
    return SimpleNamespace(rounds=[[SimpleNamespace(name=n) for n in names]])


def test_the_unseen_note_only_where_it_holds():
    wheels = SimpleNamespace(command="torque")
    search = SimpleNamespace(testbed=SimpleNamespace(wheels=wheels))
    searched = _sel(["viscous_friction", "wheel_inertia_error"])
    assert WHEEL_INERTIA_UNSEEN in _wheel_inertia_unseen(search, searched, "no missing effect")
    # the verdict already names it (named, an alternative, confounded or pinned)
    assert _wheel_inertia_unseen(search, searched, "wheel_inertia_error = 0.1 +- 0.01") == ""
    # not searched (--only), no wheels, or a speed loop (its torque shows the inertia)
    assert _wheel_inertia_unseen(search, _sel(["viscous_friction"]), "") == ""
    no_wheels = SimpleNamespace(testbed=SimpleNamespace(wheels=None))
    assert _wheel_inertia_unseen(no_wheels, searched, "") == ""
    speed = SimpleNamespace(testbed=SimpleNamespace(wheels=SimpleNamespace(command="speed")))
    assert _wheel_inertia_unseen(speed, searched, "") == ""


def test_a_wheel_friction_that_is_one_constant_torque_is_said_to_be_one():
    # a wheel biased at 200 rad/s that never reverses in a 60 deg slew: its Coulomb
    # friction is one constant torque on the table (its sign never changes), which the
    # table's rate cannot tell from a torque the model does not hold (the bearing's own
    # air-flow torque); the wheel speed that would is not fitted
    tb = load_testbed("rw-yaw")
    tb = tb.replace(wheels=dataclasses.replace(tb.wheels, speeds=(200.0,)))
    run = ab.slew(
        tb, angle_deg=60.0, duration=20.0, seed=6, effects={"wheel_coulomb_friction": 2e-5}
    )
    assert run.log.column("ws1").min() > 100.0  # never near zero
    found = ab.discrepancy(tb, [run.log])
    assert "wheel_coulomb_friction" in found.effects, str(found)
    pair = ("wheel_coulomb_friction", "constant torque about z")
    assert pair in found.confounded, str(found)
    assert "through zero" in found.experiments[" + ".join(pair)]
    assert "cannot be told from a constant torque about z" in found.verdict
