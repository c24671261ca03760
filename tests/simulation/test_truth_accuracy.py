"""The simulated truth is integrated well below what a replay of its log resolves.

Oracle: CasADi's CVODES at 1e-13 relative and absolute tolerance on the Model's own
continuous dynamics, sample by sample with the run's inputs held (the same zero-order
hold), against the replay's resolution of a noise-free attitude (1e-6 rad).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import airbearing as ab
from airbearing import quaternion as quat
from airbearing.analysis.simulation.truth_accuracy import (
    TRUTH_ACCURACY,
    raise_levels,
    sample_errors,
    truth_tolerance,
)
from airbearing.errors import InputError

RESOLUTION = 1e-6  # rad, the replay's resolution of a noise-free attitude


def _cvodes_states(run) -> np.ndarray:
    """The run's true states at the end of each sample, integrated by CVODES from its
    first state with its inputs held over each sample."""
    m, n = run.model, len(run.t)
    x, u, p = ca.SX.sym("x", m.nx), ca.SX.sym("u", m.nu), ca.SX.sym("p", m.n_p)
    dae = {"x": x, "p": ca.vertcat(u, p), "ode": m.f(x, u, p)}
    opts = {"abstol": 1e-13, "reltol": 1e-13}
    F = ca.integrator("F", "cvodes", dae, 0.0, m.testbed.sensors.dt, opts).mapaccum(n)
    P = np.vstack([run.u.T, np.tile(m.p0[:, None], (1, n))])
    return np.asarray(F(x0=run.x[0], p=P)["xf"]).T


def _attitude_error(x: np.ndarray, ref: np.ndarray) -> float:
    q_ref = ref[:, :4] / np.linalg.norm(ref[:, :4], axis=1, keepdims=True)
    e = quat.qmul(quat.qconj(x[:, :4]), q_ref)
    return float(np.max(np.linalg.norm(2 * e[:, 1:], axis=1)))


def test_a_noise_free_spin_with_coulomb_friction_is_integrated_below_the_resolution():
    # seed 000's tabletop spun at 2 rad/s tumbles (body rates to 1.4 rad/s about x and y):
    # the Coulomb friction's sign, smoothed within 1e-3 rad/s, turns within a fraction of
    # an RK4 sub-step whenever a rate crosses zero
    tb = ab.load_testbed("seed000-tabletop")
    effects = {"coulomb_friction": 1e-5, "aero_drag": 5e-6}
    run = ab.spindown(tb, initial_rate=2.0, duration=10.0, effects=effects, attitude_noise=0.0)
    ref = _cvodes_states(run)
    # the run's sub-steps keep the sum of its samples' errors within a tenth of the
    # resolution over sqrt(200) (7e-9 rad); its largest error against CVODES measured
    # 9e-9 rad: within a tenth of the resolution
    assert _attitude_error(run.x[1:], ref) < TRUTH_ACCURACY * RESOLUTION
    assert run.substeps.min() >= 4 and run.substeps.max() > 4
    # the former fixed 4 sub-steps: 2.2e-6 rad, above the resolution itself
    old = ab.simulate(run.model, run.controller, duration=10.0, x0=run.x[0], noise=False,
                      substeps=4)  # fmt: skip
    assert _attitude_error(old.x[1:], ref) > RESOLUTION


def test_a_run_within_its_tolerance_at_four_sub_steps_is_the_fixed_four_run():
    # a noise-free CMG slew at 20 Hz integrates far below its tolerance at 4 sub-steps: the
    # default keeps them (and the same compiled loop), to the bit
    model = ab.build_model("cmg-yaw")
    controller = ab.cmg_attitude_controller(model)
    args = dict(duration=2.0, x0=model.x0(w=0.1), reference=(1.0, 0.0, 0.0, 0.0), seed=3)
    run = ab.simulate(model, controller, **args)
    fixed = ab.simulate(model, controller, substeps=4, **args)
    assert np.all(run.substeps == 4) and np.all(fixed.substeps == 4)
    assert np.array_equal(run.x, fixed.x)


@pytest.mark.parametrize("bad", [0, -2, 2.5, True, "4"])
def test_substeps_must_be_a_positive_integer(bad):
    model = ab.build_model("cmg-yaw")
    with pytest.raises(InputError, match="substeps"):
        ab.simulate(model, ab.constant_input(model, np.zeros(model.nu)), duration=1.0,
                    x0=model.x0(), substeps=bad)  # fmt: skip


def test_the_tolerance_is_a_tenth_of_the_noise_or_resolution_over_root_n():
    model = ab.build_model("seed000-tabletop")
    att, rate = truth_tolerance(model, 400, 0.0, 3.86e-4)
    assert att == pytest.approx(0.1 * 1e-6 / 20) and rate == pytest.approx(0.1 * 3.86e-4 / 20)
    assert truth_tolerance(model, 400, 1e-3, 0.0) == pytest.approx(
        (0.1 * 1e-3 / 20, 0.1 * 1e-7 / 20)
    )


def test_levels_rise_where_the_error_is():
    tol = (1.0, 1.0)
    level = np.zeros(5, dtype=int)
    small = (np.full(5, 0.1), np.zeros(5))
    assert raise_levels(small, tol, level, 4) is None  # shares sum to 0.5: within
    # one sample carries nearly all of it: only it goes up (to 1/256 of its share)
    err = (np.array([0.01, 0.01, 3.0, 0.01, 0.01]), np.zeros(5))
    assert raise_levels(err, tol, level, 4).tolist() == [0, 0, 1, 0, 0]
    # the rate's share counts too; a sample at the last level stays there
    err = (np.zeros(5), np.array([0.0, 0.0, 0.0, 0.0, 5.0]))
    assert raise_levels(err, tol, np.array([0, 0, 0, 0, 3]), 4) is None


@pytest.fixture(scope="module")
def lagged_slew():
    # a noise-free 180-deg yaw slew of the 3-dof CMG rig whose gyro lags by 10 ms (a fifth
    # of a sample: the lag's update sees its source change most within a sub-step)
    tb = ab.load_testbed("cmg-3dof")
    return ab.slew(tb, duration=6.0, effects={"sensor_lag": 0.01}, ideal=True, seed=1)


def test_a_lagged_gyro_within_its_tolerance_keeps_four_sub_steps(lagged_slew):
    # the lagged rates at 4 sub-steps are 3.8e-11 rad/s off CVODES (the body rates 3.3e-11)
    # against a tolerance of 9.1e-10: the run keeps 4 sub-steps, to the bit. (Its lag's
    # step-doubling errors summed as if they accumulated, 7.9e-10, refined 13 samples: a
    # lag forgets its error within its time constant, so only what it carries counts)
    run, model = lagged_slew, lagged_slew.model
    rate_tol = truth_tolerance(model, len(run.t), 0.0, 0.0)[1]
    ref = _cvodes_states(run)
    lag = list(model.lag_index)
    assert np.max(np.abs(run.x[1:, lag] - ref[:, lag])) < rate_tol
    assert np.all(run.substeps == 4)
    fixed = ab.simulate(model, run.controller, duration=6.0, x0=run.x[0], noise=False,
                        reference=run.reference, seed=1, substeps=4)  # fmt: skip
    assert np.array_equal(run.x, fixed.x)


def test_a_lagged_rate_off_its_integration_is_refined(lagged_slew):
    # one sample whose lagged rate is 10 tolerances off what its integration gives (the
    # step doubling's own finer step does not reach it): the check counts it (16/15 of it,
    # plus the next sample's share of the decay exp(-dt/tau) = 7e-3) and refines that sample
    run, model = lagged_slew, lagged_slew.model
    rate_tol = truth_tolerance(model, len(run.t), 0.0, 0.0)
    x = run.x.copy()
    k = 60
    x[k + 1, list(model.lag_index)] += 10 * rate_tol[1]
    level = np.zeros(len(run.t), dtype=int)
    before = sample_errors(model, run.x, run.u, model.p0, (4,), level)
    after = sample_errors(model, x, run.u, model.p0, (4,), level)
    extra = after[1].sum() - before[1].sum()
    assert extra == pytest.approx(16 / 15 * 10 * rate_tol[1], rel=0.05)
    assert raise_levels(before, rate_tol, level, 4) is None
    new = raise_levels(after, rate_tol, level, 4)
    assert new is not None and new[k] == 1
