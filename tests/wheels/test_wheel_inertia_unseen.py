"""A wheel inertia error the discrepancy search cannot see is said to be unseen.

With torque-commanded wheels the body's outputs see a wheel's spin-axis inertia only
through ``J - Iw`` (a part in a thousand of the yaw inertia on ``rw-yaw``); the logged
wheel speeds, whose slope would show it, only start each window. A 10 % wheel inertia
error in a slew then leaves the body's rate as the nominal model predicts it, and "no
missing effect" alone would read as if the wheels were checked: the verdict must say that
these logs hardly show ``wheel_inertia_error`` and how to measure it.
"""

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
