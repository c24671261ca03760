"""Attitude-only (motion-capture) logs of a reaction-wheel slew.

The slew's loop needs a gyro; a lab with a gyro-less testbed file (``sensors.gyro =
false``) logs the camera's attitude. On a yaw-only rig the slew log's ``yaw`` is the
loop's own yaw, the gyro's integral: dropping ``wz`` leaves an attitude whose error is a
random walk of the gyro noise, and the search read that log with a gyro-less testbed and
named ``inertia_error`` and ``yaw_imbalance`` where nothing was hidden.
:func:`attitude_only` writes the camera's attitude: the truth plus white noise of the
testbed's ``attitude_noise``.
"""

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

import airbearing as ab
from airbearing.analysis.simulation.attitude_only import attitude_only
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed

LEVEL = 0.001  # test level of the noise checks: a correct log fails one in a thousand runs


@pytest.fixture(scope="module")
def yaw_slew():
    # 40 s at 20 Hz, the slew on the built-in one-wheel yaw rig, nothing hidden
    return ab.slew(load_testbed("rw-yaw"), duration=40.0, seed=3).log


def _white_at(e, sigma):
    """``e`` is white noise of 1-sigma ``sigma``: chi-square of its variance and Ljung-Box
    of its first 10 lags, each at ``LEVEL`` (two-sided for the variance)."""
    n = e.size
    chi2 = float(np.sum(e**2) / sigma**2)
    p_var = 2 * min(stats.chi2.sf(chi2, n), stats.chi2.cdf(chi2, n))
    p_lb = float(acorr_ljungbox(e, lags=[10])["lb_pvalue"].iloc[0])
    return p_var, p_lb


def test_a_yaw_rig_s_slew_log_logs_the_gyro_integral_as_its_yaw(yaw_slew):
    # the cause of the false names: the slew's yaw is not a camera's (white) yaw
    e = np.unwrap(yaw_slew.data["yaw"].to_numpy()) - yaw_slew.data["true_yaw"].to_numpy()
    _, p_lb = _white_at(e, load_testbed("rw-yaw").sensors.attitude_noise)
    assert p_lb < LEVEL


def test_the_attitude_only_log_has_the_camera_s_white_yaw_and_no_rate(yaw_slew):
    tb, log = attitude_only(yaw_slew, seed=5)
    assert not tb.sensors.gyro
    assert tb.sensors.attitude_noise == load_testbed("rw-yaw").sensors.attitude_noise
    assert "wz" not in log.data.columns
    assert {"ws1", "wc1"} <= set(log.data.columns)
    e = log.data["yaw"].to_numpy() - log.data["true_yaw"].to_numpy()
    p_var, p_lb = _white_at(e, tb.sensors.attitude_noise)
    assert p_var > LEVEL and p_lb > LEVEL


def test_a_three_axis_attitude_only_log_turns_the_true_attitude_by_white_noise():
    run = ab.slew(
        load_testbed("rw-3axis"), duration=5.0, axis=(0.3, 1.0, 0.2), angle_deg=30.0, seed=1
    )
    tb, log = attitude_only(run.log, attitude_noise=2e-3, seed=2)
    d = log.data
    assert not ({"wx", "wy", "wz", "gx", "gy", "gz"} & set(d.columns))
    q = d[["qw", "qx", "qy", "qz"]].to_numpy()
    q_true = d[[f"true_{k}" for k in ("qw", "qx", "qy", "qz")]].to_numpy()
    # the small rotation q_true^-1 q: its vector part is n / 2 for |n| << 1
    dq = ab.quaternion.qmul(ab.quaternion.qconj(q_true), q)
    n = 2 * dq[:, 1:] * np.sign(dq[:, :1])
    p_var, p_lb = _white_at(n.ravel(), 2e-3)
    assert p_var > LEVEL and p_lb > LEVEL


def test_a_log_without_its_truth_is_refused(yaw_slew):
    data = yaw_slew.data.drop(columns=["true_yaw"])
    with pytest.raises(InputError, match="missing column 'true_yaw'"):
        attitude_only(ab.Log(data, source="lab.csv", testbed=yaw_slew.testbed))


@pytest.mark.slow  # a discrepancy search (compiles on a cold cache)
def test_a_null_attitude_only_yaw_slew_names_nothing(yaw_slew):
    tb, log = attitude_only(yaw_slew, seed=5)
    found = ab.discrepancy(tb, [log])
    assert not found.effects, str(found)
