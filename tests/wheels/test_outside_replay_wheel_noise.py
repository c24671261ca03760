"""``replay --json`` gives each wheel's speed noise, as ``discrepancy --json`` does.

The replay weights each wheel's residual by its own noise level (noise floor from the
data); its JSON lists those levels in wheel order (``wheel_speed_noise_per_wheel``)
beside their RMS ``wheel_speed_noise``. Wheel 2 of ``rw-3axis`` gets a tachometer 5 x
noisier than the testbed's ``speed_noise`` and must stand out.
"""

import numpy as np
import pytest

import airbearing as ab
from airbearing.io.log import Log
from airbearing.io.testbed import load_testbed

EXTRA = 0.05  # rad/s, white noise added to wheel 2's speed: 5 x the testbed's 0.01


def test_the_replay_json_lists_each_wheel_s_noise():
    tb = load_testbed("rw-3axis")
    log = ab.slew(tb, angle_deg=30.0, axis=(0.3, 1.0, 0.2), duration=10.0, seed=6).log
    data = log.data.copy()
    data["ws2"] = data["ws2"] + EXTRA * np.random.default_rng(8).standard_normal(len(data))
    j = ab.replay(tb, [Log(data, source="noisy-ws2.csv", testbed=tb)]).to_json()
    levels = np.asarray(j["wheel_speed_noise_per_wheel"])
    assert levels.shape == (tb.wheels.n,)
    # the RMS over the wheels is the existing key, to rounding
    assert np.sqrt(np.mean(levels**2)) == pytest.approx(j["wheel_speed_noise"], rel=1e-12)
    # wheel 2's level is about hypot(0.05, 0.01) = 0.051 rad/s, the others' about 0.01
    # (each within about 25 % on 200 rows): a factor 3 apart is far from both
    assert levels[1] > 3 * np.delete(levels, 1).max(), levels
    assert levels[1] == pytest.approx(np.hypot(EXTRA, 0.01), rel=0.3), levels
