"""The three-axis replay's sixth-order step (Butcher's seven-stage scheme).

Oracles: the order itself (halving the step of a sixth-order scheme divides a smooth
motion's error by 2^6 = 64; a wrong coefficient drops the order to 1-3) against the same
scheme at 64 sub-steps, and the classical RK4 at 64 sub-steps (an independent scheme) for
the value. One interval of 0.2 s of seed 004's platform spinning at 1.5 rad/s (0.3 rad per
interval) with a CM offset and a viscous friction: every torque of the free body acts.
CasADi's virtual machine: no compilation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from airbearing import quaternion as quat
from airbearing.analysis.shooting.accuracy import integration_error, substeps_for
from airbearing.analysis.shooting.functions import replay_order, step_function
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model
from airbearing.models.runge_kutta import BUTCHER6

DT = 0.2  # s, one long interval: its error is far above round-off at 1-4 sub-steps


@pytest.fixture(scope="module")
def platform():
    tb = load_testbed("seed004-platform")
    model = build_model(tb, {"viscous_friction": 1e-5})
    x0 = model.x0(q=[0.9, 0.1, -0.2, 0.3], w=[-0.307, 0.189, -1.5])
    return model, x0


def _error(model, x0, n, ref, order=6):
    x = np.asarray(model.step_dt(n, order=order)(x0, np.zeros(model.nu), model.p0, DT)).ravel()
    e = quat.qmul(quat.qconj(x[:4]), ref[:4])
    return max(float(np.linalg.norm(2 * e[1:])), float(np.max(np.abs(x[4:7] - ref[4:7]))))


def test_the_tableau_is_consistent():
    # every stage's node inside the interval, the weights summing to one, and the
    # quadrature conditions of order 6 (sum b c^k = 1/(k+1), k < 6)
    a, b = BUTCHER6
    c = np.array([sum(row) for row in a])
    assert np.allclose(c, [0, 1 / 3, 2 / 3, 1 / 3, 1 / 2, 1 / 2, 1], atol=1e-15)
    for k in range(6):
        assert sum(bj * cj**k for bj, cj in zip(b, c, strict=True)) == pytest.approx(
            1 / (k + 1), abs=1e-15
        )


def test_the_step_is_sixth_order_and_agrees_with_rk4(platform):
    model, x0 = platform
    u = np.zeros(model.nu)
    ref = np.asarray(model.step_dt(64, order=6)(x0, u, model.p0, DT)).ravel()
    rk4 = np.asarray(model.step_dt(64)(x0, u, model.p0, DT)).ravel()
    # RK4 at 64 sub-steps (3 ms each, RK4's own error there about 1e-11) agrees with the
    # sixth-order reference; 1e-10 is a thousandth of one sixth-order step's error below
    assert np.max(np.abs(rk4 - ref)) < 1e-10
    errors = [_error(model, x0, n, ref) for n in (1, 2, 4)]
    ratios = [errors[i] / errors[i + 1] for i in range(2)]
    # 64 in the limit; 40-100 leaves room for the next term at 0.3 and 0.15 rad per step
    # (RK4's ratio is 16, a first-order slip's 2)
    assert all(40 < r < 100 for r in ratios), (errors, ratios)


def test_a_lag_state_follows_the_rate_as_with_rk4():
    # the lag states ride on the sixth-order plant step with the RK4 step's update (its
    # sub-interval's end values and slopes: fourth order), so both converge to one value
    tb = load_testbed("seed004-platform")
    model = build_model(tb, {"sensor_lag": 0.05})
    x0 = model.x0(q=[0.9, 0.1, -0.2, 0.3], w=[-0.307, 0.189, -1.5])
    u = np.zeros(model.nu)
    ref = np.asarray(model.step_dt(64)(x0, u, model.p0, DT)).ravel()
    lag = list(model.lag_index)
    errs = []
    for n in (2, 4, 8):
        x = np.asarray(model.step_dt(n, order=6)(x0, u, model.p0, DT)).ravel()
        errs.append(float(np.max(np.abs(x[lag] - ref[lag]))))
    # fourth order in the sub-interval: 16-fold per halving (10-25 for the next terms)
    assert all(10 < errs[i] / errs[i + 1] < 25 for i in range(2)), errs
    # rad/s at 25 ms sub-intervals (a 40 Hz log's one step: 1.4e-8 measured): a
    # ten-thousandth of seed 004's gyro noise (7.7e-4 rad/s)
    assert errs[-1] < 1e-7


def test_the_replay_steps_three_axes_at_sixth_order_and_a_yaw_bearing_with_rk4(platform):
    model, x0 = platform
    assert replay_order(model) == 6
    u = np.zeros(model.nu)
    a = step_function(model, 2)(x0, u, model.p0, DT)
    assert np.array_equal(np.asarray(a), np.asarray(model.step_dt(2, order=6)(x0, u, model.p0, DT)))
    from airbearing.io.testbed import testbed_from_dict

    rotor = {"kind": "platform", "name": "rotor", "body": {"dof": 1, "mass": 4.2, "inertia": 0.05}}
    yaw = build_model(testbed_from_dict(rotor))
    assert replay_order(yaw) == 4
    xy, uy = yaw.x0(w=1.0), np.zeros(yaw.nu)
    assert np.array_equal(
        np.asarray(step_function(yaw, 2)(xy, uy, yaw.p0, 0.1)),
        np.asarray(yaw.step_dt(2)(xy, uy, yaw.p0, 0.1)),
    )


def test_an_unknown_order_is_refused(platform):
    from airbearing.errors import InputError

    with pytest.raises(InputError, match="step order must be one of"):
        platform[0].step_dt(2, order=5)


def test_one_sixth_order_step_per_sample_integrates_a_50_hz_log_to_its_resolution():
    # seed 004's free oscillation at 50 Hz, noise-free attitude, 20 s: the accuracy rule
    # asks for one sub-step (RK4 needed four) and the error it measures is within the
    # rule's tolerance, the resolution over sqrt(samples)
    from airbearing.analysis.discrepancy.replay import model_for, prepare
    from airbearing.analysis.shooting.logs import ATTITUDE_SIGMA_MIN
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io.testbed import testbed_from_dict, testbed_to_dict

    d = testbed_to_dict(load_testbed("seed004-platform"))
    d["sensors"]["rate"] = 50.0
    tb = testbed_from_dict(d)
    run = free_oscillation(
        tb, initial_rate=(-0.307, 0.189, -1.5), sliders=(0.012, -0.018, 0.010), duration=20.0,
        seed=1,
    )  # fmt: skip
    _, windows, floor = prepare(tb, [run.log])
    model = model_for(tb)
    n = substeps_for(model, windows, floor)
    assert n == 1
    att, _ = integration_error(model, windows, n)
    samples = int((windows.weight > 0).sum())
    assert att <= ATTITUDE_SIGMA_MIN / np.sqrt(samples), att


def test_a_fast_wheel_speed_loop_gets_the_steps_its_stability_needs():
    # rw-3axis's wheels speed-commanded through a 30 ms driver loop, logged at 10 Hz: the
    # loop's mode (33/s) times 0.1 s is beyond the sixth-order step's stability limit
    # (2.86), so one step per sample would ring; the rule asks for dt |lambda| <= 1.4 per
    # step (three here) and those steps agree with sixteen
    from airbearing.analysis.discrepancy.replay import model_for, prepare
    from airbearing.analysis.shooting.accuracy import MAX_SUBSTEP_STIFFNESS
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io.testbed import testbed_from_dict, testbed_to_dict

    d = testbed_to_dict(load_testbed("rw-3axis"))
    d["wheels"].update(command="speed", speed_loop_tau=0.03)
    d["sensors"]["rate"] = 10.0
    tb = testbed_from_dict(d)
    run = free_oscillation(tb, initial_rate=(0.1, -0.1, 0.5), duration=10.0, seed=0)
    _, windows, _ = prepare(tb, [run.log])
    model = model_for(tb)
    n = substeps_for(model, windows)
    assert n == math.ceil(0.1 / 0.03 / MAX_SUBSTEP_STIFFNESS) == 3

    def speeds(k):  # wheel speeds after 5 s from 100 rad/s, commanded to rest
        x = model.x0(w=[0.1, -0.1, 0.5], wheels=[100.0] * 4)
        step = step_function(model, k)
        for _ in range(50):
            x = np.asarray(step(x, np.zeros(model.nu), model.p0, 0.1)).ravel()
        return x[7:11]

    fine = speeds(16)
    # rad/s: 1e-7 is a hundred-thousandth of rw-3axis's wheel-speed noise (0.01 rad/s)
    assert np.max(np.abs(speeds(n) - fine)) < 1e-7
    assert np.max(np.abs(speeds(1) - fine)) > 1e-3  # what the rule avoids
