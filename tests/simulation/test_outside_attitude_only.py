"""An attitude-only log (motion capture) holds no gyro in any form.

:func:`attitude_only` drops the rate columns and the loop's own state estimates
(``yaw_est``, ``qe_*``, ``G_*``): on a closed-loop slew they are the gyro read through the
loop (``G_*`` its low-passed rate, ``yaw_est`` its integral), which a camera's export does
not hold. The loop's commands (``Tc_*``) stay.
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.simulation.attitude_only import attitude_only
from airbearing.analysis.simulation.scenarios import slew
from airbearing.design.attitude import EXTRA_NAMES
from airbearing.design.wheels import WHEEL_EXTRA_NAMES
from airbearing.io.testbed import load_testbed

ESTIMATES = {"yaw_est", "qe_w", "qe_x", "qe_y", "qe_z", "G_x", "G_y", "G_z"}


def test_the_estimates_are_the_loops_own_columns():
    # the names dropped are the controllers' (a rename there must not leave a gyro column)
    assert ESTIMATES <= set(EXTRA_NAMES) and ESTIMATES <= set(WHEEL_EXTRA_NAMES)


def test_a_camera_log_of_a_yaw_slew_keeps_no_loop_estimate():
    run = slew(load_testbed("cmg-yaw"), angle_deg=60.0, duration=3.0, seed=1)
    assert ESTIMATES <= set(run.log.data.columns)  # the gyro log has them
    # the gyro log's G_z is the low-passed gyro: the rate a camera log must not carry
    g = run.log.data["G_z"].to_numpy()
    assert np.corrcoef(g, run.log.data["true_wz"].to_numpy())[0, 1] > 0.9
    _, log = attitude_only(run.log, attitude_noise=1e-3, seed=2)
    cols = set(log.data.columns)
    assert not ESTIMATES & cols
    assert {"Tc_x", "Tc_y", "Tc_z", "yaw", "true_yaw", "d1", "dd1"} <= cols
