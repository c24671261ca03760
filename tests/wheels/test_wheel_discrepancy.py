"""The discrepancy workflow on reaction-wheel logs: the wheel_* effects are candidates.

A yaw rig turned by one torque-commanded wheel with Coulomb friction in its bearing
(simulated with the package's own model, as every discrepancy test): the search names
``wheel_coulomb_friction`` near its value and within 3 std, with the gap after it at the
noise floor (1.5 x: the reaction-wheel issue's bound for hidden cases).
"""

import numpy as np
import pandas as pd
import pytest

import airbearing as ab
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model

DT = 0.05  # s, rw-yaw's 20 Hz
N = 800  # 40 s
FRICTION = 5e-5  # N m: a twentieth of the wheel's largest torque


@pytest.fixture(scope="module")
def friction_log():
    tb = load_testbed("rw-yaw")
    model = build_model(tb, {"wheel_coulomb_friction": FRICTION})
    p = model.params()
    t = np.arange(N) * DT
    U = np.zeros((model.nu, N))
    i = model.index("wc1", "u")[0]
    # torque steps about a bias: the wheel stays between about 150 and 250 rad/s
    U[i] = 4e-4 * np.sign(np.sin(2 * np.pi * t / 10.0))
    x0 = model.x0(wheels=[200.0])
    X = np.vstack([x0, np.asarray(model.rollout(N - 1, DT)(x0, U[:, :-1], p)).T])
    rng = np.random.default_rng(11)
    s = tb.sensors
    cols = {
        "t": t,
        "yaw": X[:, 0] + s.attitude_noise * rng.standard_normal(N),
        "wz": X[:, 1] + s.gyro_noise * rng.standard_normal(N),
        "ws1": X[:, 2] + tb.wheels.speed_noise * rng.standard_normal(N),
        "wc1": U[i],
    }
    assert np.all(X[:, 2] > 50)  # away from zero speed, where the friction changes sign
    return tb, Log(pd.DataFrame(cols), source="<rw friction>", testbed=tb)


def test_wheel_coulomb_friction_is_named(friction_log):
    tb, log = friction_log
    found = ab.discrepancy(tb, [log])
    named = found.effects
    assert "wheel_coulomb_friction" in named, str(found)
    value = float(np.ravel(named["wheel_coulomb_friction"])[0])
    std = float(np.ravel(found.effect_std["wheel_coulomb_friction"])[0])
    assert abs(value / FRICTION - 1) < 0.10  # the 10 %
    assert abs(value - FRICTION) < 3 * std
    assert found.gap_after < 1.5 * found.noise_floor


def test_a_wheel_log_without_wheel_speeds_is_refused(friction_log):
    tb, log = friction_log
    with pytest.raises(InputError, match=r"nows\.csv: missing column 'ws1'"):
        ab.discrepancy(tb, [Log(log.data.drop(columns=["ws1"]), source="nows.csv", testbed=tb)])
