"""A noise-free log (a built-in testbed's ideal sensors): the floor is the replay's
resolution, nothing below it is named, and no noise model is taken for its integration
error."""

from __future__ import annotations

import warnings

import airbearing as ab
from airbearing.analysis.shooting.logs import RATE_SIGMA_MIN


def test_a_noise_free_spin_down_names_the_friction_and_nothing_below_the_resolution():
    tb = ab.load_testbed("cmg-yaw")  # gyro_noise = 0
    run = ab.spindown(tb, initial_rate=1.0, duration=10.0, effects={"viscous_friction": 1e-4})
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no numpy warning leaks out
        found = ab.discrepancy(tb, [run.log])
    # it named aero_drag = 1.5e-16 as well, the integration's own error, once viscous
    # friction left the residual at 1e-14 rad/s
    assert set(found.effects) == {"viscous_friction"}, found.verdict
    assert abs(found.effects["viscous_friction"] - 1e-4) < 1e-10
    assert found.noise_floor == RATE_SIGMA_MIN
    doc = found.to_json()
    assert "resolution" in doc["noise_floor_source"] and doc["rate_noise"] < RATE_SIGMA_MIN
    assert doc["adequacy"]["measurement_noise"] is None  # no coloured noise in a perfect log
    # its error is the bound at the resolution (the residual alone gave 3e-20: std / bound
    # 3.5e-9), which still covers the truth
    (effect,) = doc["effects"]
    assert effect["std"] == effect["crlb"] > 0
    assert abs(effect["value"] - 1e-4) < 3 * effect["std"]
