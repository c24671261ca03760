"""The discrepancy workflow on reaction-wheel logs: the wheel_* effects are candidates.

Each case is one log simulated with the package's own model (as every discrepancy test)
and one discrepancy run, judged by the reaction-wheel issue's bounds for hidden cases: the
right effect within 10 % and 3 std, the gap after it at most 1.5 x the noise floor.

- wheel Coulomb and viscous bearing friction on ``rw-yaw`` (one torque-commanded wheel,
  open-loop torque steps: the wheel speed changes by tens of rad/s, so the two forms differ);
- the body's ``inertia_error`` on ``rw-yaw`` under the wheel attitude loop (a slew): named,
  and told from ``wheel_torque_error`` by the fitted wheel speed (the body outputs see only
  the wheel torque over ``J - Iw``: a larger body and a weaker motor give the same rate,
  not the same wheel speed);
- the air bearing's Coulomb friction in a slew from rest: named, told from the wheel
  bearing's (one torque form on the body, not on the wheel);
- a torque-constant error on ONE wheel of ``rw-3axis`` (3 + 1 wheels) during a slew: named
  per wheel, with its value on that wheel and the others near zero;
- Coulomb friction of different sizes in each wheel of ``rw-3axis`` (one wheel without):
  named per wheel;
- the confounded friction pair: the wheel held at a nearly constant speed (the command
  balances the friction), where viscous and Coulomb bearing friction are one constant
  torque: both listed in ``confounded`` with the experiment that separates them.
"""

import numpy as np
import pandas as pd
import pytest

import airbearing as ab
from airbearing.analysis.discrepancy.words import WHEEL_INERTIA_UNSEEN
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model

DT = 0.05  # s, the built-ins' 20 Hz
N = 800  # 40 s
COULOMB = 5e-5  # N m: a twentieth of the wheel's largest torque
VISCOUS = 2e-7  # N m s: 6e-5 N m at 300 rad/s
INERTIA = 0.1  # body inertia error, rw-yaw
TORQUE = 0.15  # torque-constant error of wheel 2, rw-3axis


def _open_loop(name, effects, command, speeds, seed=11):
    """A log of open-loop wheel commands ``command(t)`` (N m) from wheel speeds ``speeds``."""
    tb = load_testbed(name)
    model = build_model(tb, effects)
    p = model.params()
    t = np.arange(N) * DT
    U = np.zeros((model.nu, N))
    i = model.index("wc1", "u")[0]
    U[i] = command(t)
    x0 = model.x0(wheels=speeds)
    X = np.vstack([x0, np.asarray(model.rollout(N - 1, DT)(x0, U[:, :-1], p)).T])
    rng = np.random.default_rng(seed)
    s = tb.sensors
    cols = {
        "t": t,
        "yaw": X[:, 0] + s.attitude_noise * rng.standard_normal(N),
        "wz": X[:, 1] + s.gyro_noise * rng.standard_normal(N),
        "ws1": X[:, 2] + tb.wheels.speed_noise * rng.standard_normal(N),
        "wc1": U[i],
    }
    return tb, Log(pd.DataFrame(cols), source=f"<{name} open loop>", testbed=tb), X[:, 2]


def _judge(found, name, truth, index=0):
    """The issue's bounds: named, within 10 % and 3 std, the gap after <= 1.5 x the floor."""
    assert name in found.effects, str(found)
    value = float(np.ravel(found.effects[name])[index])
    std = float(np.ravel(found.effect_std[name])[index])
    assert abs(value / truth - 1) < 0.10, str(found)
    assert abs(value - truth) < 3 * std, str(found)
    assert found.gap_after < 1.5 * found.noise_floor, str(found)
    return value, std


@pytest.fixture(scope="module")
def coulomb_log():
    # torque steps about a bias: the wheel stays between about 150 and 250 rad/s
    tb, log, W = _open_loop(
        "rw-yaw",
        {"wheel_coulomb_friction": COULOMB},
        lambda t: 4e-4 * np.sign(np.sin(2 * np.pi * t / 10.0)),
        [200.0],
    )
    assert np.all(W > 50)  # away from zero speed, where the friction changes sign
    return tb, log


@pytest.fixture(scope="module")
def coulomb_run(coulomb_log):
    tb, log = coulomb_log
    return tb, log, ab.discrepancy(tb, [log])


@pytest.mark.slow
def test_wheel_coulomb_friction_is_named(coulomb_run):
    _, _, found = coulomb_run
    _judge(found, "wheel_coulomb_friction", COULOMB)


def test_a_wheel_log_without_wheel_speeds_is_refused(coulomb_log):
    tb, log = coulomb_log
    with pytest.raises(InputError, match=r"nows\.csv: missing column 'ws1'"):
        ab.discrepancy(tb, [Log(log.data.drop(columns=["ws1"]), source="nows.csv", testbed=tb)])


def test_wheel_viscous_friction_is_named_when_the_wheel_speed_changes():
    # small torque steps: the friction spins the wheel down from 300 to about 220 rad/s,
    # a friction torque that falls by a quarter (Coulomb friction's would not)
    tb, log, W = _open_loop(
        "rw-yaw",
        {"wheel_viscous_friction": VISCOUS},
        lambda t: 4e-5 * np.sign(np.sin(2 * np.pi * t / 4.0)),
        [300.0],
    )
    assert np.ptp(W) > 50
    found = ab.discrepancy(tb, [log])
    _judge(found, "wheel_viscous_friction", VISCOUS)
    assert "wheel_coulomb_friction" not in found.effects
    assert not any("wheel_coulomb_friction" in pair for pair in found.confounded)


@pytest.mark.slow
def test_the_friction_pair_at_a_nearly_constant_wheel_speed_is_confounded():
    # the command balances the viscous friction at 300 rad/s (6e-5 N m) with steps about
    # it: the wheel speed stays within about 1 % and both forms are one constant torque
    tb, log, W = _open_loop(
        "rw-yaw",
        {"wheel_viscous_friction": VISCOUS},
        lambda t: VISCOUS * 300.0 + 4e-5 * np.sign(np.sin(2 * np.pi * t / 4.0)),
        [300.0],
    )
    assert np.ptp(W) < 0.02 * 300
    found = ab.discrepancy(tb, [log])
    pair = {"wheel_viscous_friction", "wheel_coulomb_friction"}
    assert any(set(p) == pair for p in found.confounded), str(found)
    (key,) = [k for k in found.experiments if set(k.split(" + ")) == pair]
    assert "vary the wheel speed" in found.experiments[key]
    # one of the two is named, never both, and its error holds the choice: the truth (or
    # the other form's equivalent constant torque) within 3 std
    named = pair & set(found.effects)
    assert len(named) == 1, str(found)
    assert found.gap_after < 1.5 * found.noise_floor
    if "wheel_viscous_friction" in named:
        _judge(found, "wheel_viscous_friction", VISCOUS)
    else:
        _judge(found, "wheel_coulomb_friction", VISCOUS * 300.0)
    # the wheel speeds are fitted: a wheel inertia error is never said to be unseen by the
    # body (alone, without the friction, its fit may still run to a bound: a wheel of
    # infinite inertia ignores the unbalanced command, as the friction makes it)
    for c in found.candidates:
        if c.name == "wheel_inertia_error":
            assert WHEEL_INERTIA_UNSEEN not in (c.reason or "")
    assert WHEEL_INERTIA_UNSEEN not in found.verdict


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_body_inertia_error_on_a_wheel_yaw_rig_is_told_from_the_motor_by_the_wheel_speed():
    tb = load_testbed("rw-yaw")
    log = ab.slew(tb, effects={"inertia_error": INERTIA}, duration=40.0, seed=3).log
    found = ab.discrepancy(tb, [log])
    _judge(found, "inertia_error", INERTIA)
    # the body's rate sees the wheel torque over J - Iw: a torque-constant error of
    # 1 / (1 + e) - 1 gives the same rate (to the wheel's part in a thousand of J), but
    # not the same wheel speed (its slope is (1 + k) tau / Iw): the fitted wheel speeds
    # tell them apart (when they only started each window, the pair was confounded)
    assert set(found.effects) == {"inertia_error"}, str(found)
    assert ("inertia_error", "wheel_torque_error") not in found.confounded, str(found)
    # ... but only the wheels' motors act: scaling the body's inertia, the wheel's and the
    # motor torque together leaves every motion alone, so the torque error together with a
    # wheel inertia error, both 1 / (1 + e) - 1, is the same log (test_wheel_scale_confounding)
    pair = ("inertia_error", "wheel_torque_error + wheel_inertia_error")
    assert pair in found.confounded, str(found)


@pytest.mark.slow
def test_a_torque_error_on_one_of_four_wheels_is_named_on_that_wheel():
    tb = load_testbed("rw-3axis")
    truth = [0.0, TORQUE, 0.0, 0.0]
    # 20 s of the slew, not 30 s (two thirds of the cost): wheel 2's error within 0.02 % and
    # 0.01 std (30 s: 0.4 %, 0.5 std), the others at a twentieth of what the test allows
    run = ab.slew(
        tb, effects={"wheel_torque_error": truth}, duration=20.0, axis=(0.3, 1.0, 0.2),
        angle_deg=90.0, seed=3,
    )  # fmt: skip
    # one effect hidden and judged: the search stops after naming it (max_effects=1; a
    # second round of the ~20 rw-3axis candidates would double the cost and is asserted
    # nowhere here: a search naming nothing more is test_wheel_viscous_friction_is_named...)
    found = ab.discrepancy(tb, [run.log], max_effects=1)
    value, std = _judge(found, "wheel_torque_error", TORQUE, index=1)
    values = np.ravel(found.effects["wheel_torque_error"])
    stds = np.ravel(found.effect_std["wheel_torque_error"])
    assert values.size == 4  # per wheel
    others = [0, 2, 3]
    assert np.all(np.abs(values[others]) < np.maximum(3 * stds[others], 0.1 * TORQUE))


@pytest.mark.slow
def test_coulomb_friction_of_each_of_four_wheels_is_named_per_wheel():
    tb = load_testbed("rw-3axis")
    truth = [2e-5, 4e-5, 0.0, 1e-5]  # N m; wheel 3 without friction
    # 30 s, not 40 s (a third of the cost): per wheel within 4.3 %
    # and 1.3 std of the truth (40 s: 1.9 %, 1.1 std); at 20 s the one-value form is named
    # instead, so the log length still decides what this test checks
    run = ab.slew(
        tb, effects={"wheel_coulomb_friction": truth}, duration=30.0, axis=(0.3, 1.0, 0.2),
        angle_deg=90.0, seed=3,
    )  # fmt: skip
    found = ab.discrepancy(tb, [run.log], max_effects=1)  # one effect: as above
    for i in (0, 1, 3):
        _judge(found, "wheel_coulomb_friction", truth[i], index=i)
    value = float(np.ravel(found.effects["wheel_coulomb_friction"])[2])
    std = float(np.ravel(found.effect_std["wheel_coulomb_friction"])[2])
    assert value < 3 * std  # >= 0 by its physical range


@pytest.mark.slow
def test_air_bearing_and_wheel_bearing_friction_in_a_slew_from_rest_are_told_apart():
    # a slew from rest: the wheel turns against the body (J w + Iw (W + w) = 0), so the air
    # bearing's Coulomb friction -f sign(w) and the wheel bearing's reaction f sign(W) are
    # one torque form on the body; not on the wheel: the air bearing's friction leaves the
    # wheel's absolute speed W + w alone, the wheel bearing's slows it. With the wheel
    # speeds fitted the air bearing's is named alone (they were confounded when the wheel
    # speeds only started each window)
    tb = load_testbed("rw-yaw")
    friction = 1e-4  # N m
    log = ab.slew(tb, effects={"coulomb_friction": friction}, duration=40.0, seed=5).log
    found = ab.discrepancy(tb, [log])
    _judge(found, "coulomb_friction", friction)
    assert set(found.effects) == {"coulomb_friction"}, str(found)
    assert not any("wheel_coulomb_friction" in p for p in found.confounded), str(found)
