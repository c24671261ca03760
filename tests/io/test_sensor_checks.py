"""The sensors against each other and the testbed: a dead, reversed, mis-scaled or saturated
gyro axis is found, named and refused by the fits (a bias or a clean log is not); a
channel far noisier than the testbed says is named."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import airbearing as ab
from airbearing.errors import InputError
from airbearing.io.log import Log


@pytest.fixture(scope="module")
def free():
    """A free oscillation of seed004-platform, gyro and quaternion, 20 s at 20 Hz."""
    tb = ab.load_testbed("seed004-platform")
    log = ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=20.0, seed=3).log
    return tb, log.data


def _with(tb, data, **change):
    d = data.copy()
    for col, f in change.items():
        d[col] = f(d[col].to_numpy())
    return Log(d, source="lab.csv", testbed=tb)


def test_a_clean_log_and_a_gyro_bias_agree(free):
    tb, data = free
    assert _with(tb, data).quality.gyro_disagreement == ()
    # a 0.05 rad/s bias (an effect the discrepancy names) changes no slope
    assert _with(tb, data, wx=lambda w: w + 0.05).quality.gyro_disagreement == ()


@pytest.mark.parametrize(
    "change, words",
    [
        ({"wx": lambda w: 0 * w}, "gyro wx reads 0 x"),
        ({"wy": lambda w: -w}, "gyro wy reads -0.99"),  # measured -0.999 (attitude noise)
        ({"wz": lambda w: np.degrees(w)}, "gyro wz reads 57.2 x"),  # measured 57.2
        ({"wz": lambda w: np.clip(w, -0.3, 0.3)}, "gyro wz sits at its largest reading 0.3"),
    ],
    ids=["dead", "reversed", "deg-as-rad", "saturated"],
)
def test_a_bad_gyro_axis_is_named_and_refused(free, change, words):
    tb, data = free
    log = _with(tb, data, **change)
    (why,) = log.quality.gyro_disagreement
    assert why.startswith(words), why
    check = ab.check_log(log)
    assert not check.tools["identify"][0] and not check.tools["discrepancy"][0]
    for fit in (lambda: ab.identify(tb, [log]), lambda: ab.discrepancy(tb, [log])):
        with pytest.raises(InputError, match="lab.csv: " + words.replace(".", "\\.")):
            fit()


def test_a_quaternion_in_the_wrong_component_order_is_found(free):
    tb, data = free
    d = data.copy()
    d[["qw", "qx", "qy", "qz"]] = data[["qx", "qy", "qz", "qw"]].to_numpy()  # xyzw as wxyz
    why = Log(d, source="lab.csv", testbed=tb).quality.gyro_disagreement
    assert why and "component order" in why[0]


def test_a_gyro_integrated_yaw_agrees_and_a_dead_gyro_does_not():
    # a CMG log whose yaw is the controller's integral of its own gyro (seed 001 eq. 21)
    tb = ab.load_testbed("cmg-yaw")
    t = np.arange(400) * 0.05
    wz = 0.3 * np.sin(0.5 * t) + 1e-3 * np.random.default_rng(1).standard_normal(t.size)
    cols = {"t": t, "yaw": np.cumsum(wz) * 0.05, "wz": wz}
    cols |= {f"d{i}": np.zeros(t.size) for i in range(1, 5)}
    ok = Log(pd.DataFrame(cols), source="cmg.csv", testbed=tb)
    assert ok.quality.gyro_disagreement == ()
    dead = Log(pd.DataFrame(cols | {"wz": 0 * wz}), source="cmg.csv", testbed=tb)
    assert dead.quality.gyro_disagreement[0].startswith("gyro wz reads 0 x")


def test_a_channel_far_noisier_than_the_testbed_says_is_named():
    # motion capture of the README's rig: 1 mrad declared; the same log in degrees reads
    # 57 mrad of "noise" (a unit read wrong), which log check names
    rig = ab.read_testbed("examples/mocap-spin/rig.toml")
    t = np.arange(600) / rig.sensors.rate
    yaw = 2.0 * t - 0.01 * t**2 + 1e-3 * np.random.default_rng(2).standard_normal(t.size)
    ok = Log(pd.DataFrame({"t": t, "yaw": yaw}), source="rad.csv", testbed=rig)
    assert ok.quality.noise_warnings == ()
    deg = Log(pd.DataFrame({"t": t, "yaw": np.degrees(yaw)}), source="deg.csv", testbed=rig)
    (why,) = deg.quality.noise_warnings
    assert why.startswith("yaw noise") and "x the testbed's sensors.attitude_noise 0.001" in why
    assert ab.check_log(deg).to_json()["noise_warnings"] == [why]
