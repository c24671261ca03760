"""The wheel-speed noise floor of a wheel held at its ``max_speed``.

FORMATS.md ``[wheels]``: the motor gives no torque that would drive ``|W|`` past
``max_speed``. A torque-commanded wheel's noise floor takes the differences of its
speed less the commanded torque's integral (shooting/noise_floor.py); at the speed limit
that integral must stop as the wheel does, or the command's sample-to-sample noise
(divided by the small wheel inertia) is taken for tachometer noise.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from airbearing.analysis.shooting.logs import noise_floor, replay_data
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.io.testbed import load_testbed


def test_a_wheel_at_its_speed_limit_shows_the_tachometer_s_noise():
    tb = load_testbed("rw-yaw")  # speed_noise 0.01 rad/s, max_speed 628.32 rad/s
    tb = tb.replace(wheels=dataclasses.replace(tb.wheels, speeds=[600.0]))
    rng = np.random.default_rng(3)
    t = np.arange(600) / tb.sensors.rate
    # a noisy command that keeps asking to speed the wheel up: at the limit within 2 s
    wc = 4e-4 + 2e-4 * rng.standard_normal(t.size)
    log = simulate_on_times(tb, t, initial_rate=0.0, inputs={"wc1": wc}, seed=4)
    ws = log.data["ws1"].to_numpy()
    assert np.all(ws[60:] > 0.99 * tb.wheels.max_speed)  # held at the limit
    floor = noise_floor(replay_data(tb, log)).wheel_axes[0]
    # 600 samples: the MAD of overlapping fourth differences scatters by about 8 %
    # (0.0089-0.0109 over seeds 0-4, saturated or not); 25 % is 3 of those. The
    # command's integral past the limit gave 0.17 rad/s, 17 times the noise.
    assert floor == pytest.approx(tb.wheels.speed_noise, rel=0.25)
