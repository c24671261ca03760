"""The discrepancy JSON's per-wheel speed noise: ``wheel_speed_noise_per_wheel``.

Each wheel's residual is weighted by its own estimated noise level (a rig's tachometers
need not be alike); the JSON gives those levels in wheel order beside their RMS,
``wheel_speed_noise``. Here wheel 3 of ``rw-3axis`` (3 + 1 wheels) gets a noisier
tachometer than the testbed's ``speed_noise``, and its level must be the one that stands out.
"""

import numpy as np
import pytest

import airbearing as ab
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed

EXTRA = 0.05  # rad/s, added white noise of wheel 3's speed: 5 x the testbed's 0.01


@pytest.fixture(scope="module")
def found():
    tb = load_testbed("rw-3axis")
    log = ab.slew(tb, angle_deg=30.0, axis=(0.3, 1.0, 0.2), duration=10.0, seed=4).log
    data = log.data.copy()
    data["ws3"] = data["ws3"] + EXTRA * np.random.default_rng(7).standard_normal(len(data))
    # one candidate: the JSON's floor keys, not the search, are under test (about 1 s)
    return tb, ab.discrepancy(
        tb, [Log(data, source="noisy-ws3.csv", testbed=tb)], only=["viscous_friction"]
    ).to_json()


def test_one_level_per_wheel_whose_rms_is_wheel_speed_noise(found):
    tb, j = found
    levels = np.asarray(j["wheel_speed_noise_per_wheel"])
    assert levels.shape == (tb.wheels.n,)
    assert np.all(np.isfinite(levels)) and np.all(levels > 0)
    # the RMS over the wheels is the existing key, to rounding
    assert np.sqrt(np.mean(levels**2)) == pytest.approx(j["wheel_speed_noise"], rel=1e-12)


def test_the_levels_are_in_wheel_order(found):
    _, j = found
    levels = np.asarray(j["wheel_speed_noise_per_wheel"])
    # wheel 3's level is about sqrt(0.05^2 + 0.01^2) = 0.051 rad/s, the others' about
    # 0.01 (each estimate within about 25 % on 200 rows): a factor 3 is far from both
    others = np.delete(levels, 2)
    assert levels[2] > 3 * others.max(), levels
    assert levels[2] == pytest.approx(np.hypot(EXTRA, 0.01), rel=0.3), levels
