"""The replay integrates a three-axis log to its resolution.

Oracle: an independent RK4 rollout with 64 sub-steps per sample (error below 1e-10 rad on
this motion) from the same window starts. Seed 004's free oscillation (rates to 1.5
rad/s, 20 Hz) with a noise-free attitude: two RK4 sub-steps, the old default, drift
3.9e-6 rad over its 30 s, four times the 1e-6 rad a noise-free attitude is weighted at,
and biased per-axis viscous frictions by up to 3.2 standard errors (coverage study, case
b). The replay's three-axis step is sixth order (one step per sample drifts 9.5e-8 rad
here, two 1.5e-9).
"""

from __future__ import annotations

import math

import numpy as np


def _platform(attitude_noise=0.0):
    from bench_scripts import load

    return load("coverage_study").platform_logs(14, "a", attitude_noise)


def test_a_noise_free_attitude_is_integrated_to_the_resolution():
    from airbearing import quaternion as quat
    from airbearing.analysis.discrepancy.replay import model_for, prepare, substeps_for
    from airbearing.analysis.shooting.functions import step_function
    from airbearing.analysis.shooting.logs import ATTITUDE_SIGMA_MIN
    from airbearing.analysis.simulation.on_times import rollout_dt

    tb, logs = _platform()
    _, windows, floor = prepare(tb, logs)
    model = model_for(tb)
    n = substeps_for(model, windows, floor)
    L = windows.length
    # the replay's step against the independent RK4
    fitted = step_function(model, n).mapaccum("rollout", L - 1, [0], [0])
    exact = rollout_dt(model, L - 1, 64)
    drift = 0.0
    for j in range(windows.n):  # the windows' errors add up along the segment
        args = (windows.x0[j], windows.u[j, : L - 1].T, model.p0, windows.dt[j][None, :])
        a, b = np.asarray(fitted(*args)).T, np.asarray(exact(*args)).T
        e = quat.qmul(quat.qconj(a[:, :4]), b[:, :4])
        drift += float(np.max(np.linalg.norm(2 * e[:, 1:], axis=1)))
    # smooth over the segment, the drift acts on a value as sqrt(n) white errors of its size
    # would: at most the resolution over sqrt(n) (600 samples: 4.1e-8 rad)
    n_samples = int((windows.weight > 0).sum())
    assert drift <= ATTITUDE_SIGMA_MIN / math.sqrt(n_samples), (n, drift)
    # and no more sub-steps than that needs (two here; one leaves 9.5e-8 rad)
    assert n <= 2, n


def test_without_the_floor_the_rotation_rule_alone():
    # identification's callers pass no floor: one sixth-order step per sample (0.075 rad
    # at most here, under the rule's 0.2)
    from airbearing.analysis.discrepancy.replay import model_for, prepare, substeps_for

    tb, logs = _platform()
    _, windows, _ = prepare(tb, logs)
    assert substeps_for(model_for(tb), windows) == 1


def test_a_noisy_attitude_keeps_the_default_sub_steps():
    # a motion-capture attitude (1e-3 rad) dwarfs one step's drift (9.5e-8 rad over the
    # 30 s): no more sub-steps, no more cost; its noise is seen through the motion (8th
    # differences: 1.03e-3 rad, 8e-10 on the noise-free attitude)
    from airbearing.analysis.discrepancy.replay import (
        attitude_noise,
        model_for,
        prepare,
        substeps_for,
    )

    tb, logs = _platform(1e-3)
    _, windows, floor = prepare(tb, logs)
    assert substeps_for(model_for(tb), windows, floor) == 1
    assert 0.9e-3 <= attitude_noise(windows) <= 1.1e-3
    _, windows, _ = prepare(*_platform())
    assert attitude_noise(windows) < 1e-7
