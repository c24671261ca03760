"""Honest standard errors of the CMG (momentum-exchange) identification.

Oracle: the truth of the simulation, ``cmg-yaw`` with ``inertia_error = 0.14``
(J_z = 0.00283 x 1.14 = 0.0032262 kg m^2), gyro noise 5e-4 rad/s, no lowpass, one 180 deg
slew of 40 s at 20 Hz per seed. The white-noise least-squares error (``std_white``) left a
drifting gyro (``wz += 1e-4 t``) 17 of its sigmas off without a warning, and a missing
viscous friction 39. The coverage study below is the one in
docs/explanation/honest-answers.md.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.signal import lfilter

from airbearing import load_testbed, slew
from airbearing.analysis.identification.cmg_inertia import identify_cmg_inertia
from airbearing.io.log import Log
from airbearing.io.testbed import Sensors

J_TRUE = 0.00283 * 1.14  # kg m^2: the built-in CAD value times (1 + inertia_error)
C_TRUE = 2e-5  # N m s, viscous friction of the truth in the friction cases
SIGMA = 5e-4  # rad/s, gyro noise
SEEDS = range(10)
# the brief's bar: the truth within 3 reported sigmas in at least 9 of 10 seeds (an honest
# Gaussian error misses 3 sigmas with probability 0.27 %, so one miss is already luck)
COVER_SIGMAS, MIN_COVERED = 3.0, 9


@functools.cache
def _testbed():
    # one object: the logs carry it, so identification reuses each log's cached quality
    # (io.quality's rule, most of a fit's time) instead of assessing the log twice
    sensors = Sensors(rate=20.0, gyro_noise=SIGMA, lowpass=1.0)
    return load_testbed("cmg-yaw").replace(sensors=sensors)


@functools.cache
def _log(case: str, seed: int) -> Log:
    # cached: the two viscous tests fit the same logs (with and without the friction term)
    tb = _testbed()
    effects = {"inertia_error": 0.14}
    if case.startswith("viscous"):
        effects["viscous_friction"] = C_TRUE
    log = slew(tb.replace(effects=effects), duration=40.0, seed=seed).log
    d = log.data.copy()
    if case == "drift":
        d["wz"] = d["wz"] + 1e-4 * d["t"]  # a gyro bias drifting 1e-4 rad/s per s
    elif case == "ar1":  # AR(1) gyro noise, coefficient 0.95 (1 s correlation), on the white
        rng = np.random.default_rng(100 + seed)
        phi = 0.95
        u = rng.normal(0.0, SIGMA * math.sqrt(1 - phi**2), len(d))
        d["wz"] = d["wz"] + lfilter([1.0], [1.0, -phi], u, zi=[phi * rng.normal(0.0, SIGMA)])[0]
    return Log(d, source=f"{case}-{seed}.csv", testbed=tb)


def _runs(case: str, friction=None):
    tb = _testbed()
    return [identify_cmg_inertia(tb, [_log(case, s)], friction=friction) for s in SEEDS]


def _z(res) -> float:
    return (res.inertia - J_TRUE) / res.std_inertia


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_white_noise_keeps_the_white_error():
    """Within the model the sandwich is the white-noise error (measured 1.00-1.10 times it
    on these seeds, 1.00-1.22 on 30 more, median 1.00: the HAC's own sampling error on 800
    samples), the truth is covered, nothing is warned."""
    runs = _runs("clean")
    ratio = np.array([r.std_inertia / r.std_white[0] for r in runs])
    assert np.all(ratio >= 1.0) and np.all(ratio <= 1.25), ratio
    assert np.median(ratio) <= 1.05, ratio
    assert sum(abs(_z(r)) <= COVER_SIGMAS for r in runs) >= MIN_COVERED
    assert not any(r.warnings for r in runs), [r.warnings for r in runs if r.warnings]
    j = runs[0].to_json()
    assert j["std_white"] == pytest.approx(runs[0].std_white[0]) and j["std"] >= j["std_white"]
    # a white residual: AIC picks order 0 or a weak AR (coefficient sums measured <= 0.09)
    assert all(abs(r.details["covariance"]["ar_sum"]) < 0.2 for r in runs)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_drifting_gyro_is_covered_and_warned():
    """Case (b): the drift's slow residual widens the error (measured 7.8-10.8 times the
    white one) so that the truth is covered, and the 2.2-sigma residual is warned about."""
    runs = _runs("drift")
    assert sum(abs(_z(r)) <= COVER_SIGMAS for r in runs) >= MIN_COVERED, [_z(r) for r in runs]
    assert all(abs((r.inertia - J_TRUE) / r.std_white[0]) > 10 for r in runs)  # white: 16-18
    assert all(any("gyro sigmas" in w for w in r.warnings) for r in runs)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_coloured_gyro_noise_is_covered():
    """AR(1) gyro noise (0.95): the errors widen 2.6-3.8 times and cover the truth; the
    correlated residual is named."""
    runs = _runs("ar1")
    assert sum(abs(_z(r)) <= COVER_SIGMAS for r in runs) >= MIN_COVERED, [_z(r) for r in runs]
    assert all(any("correlated" in w for w in r.warnings) for r in runs)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_viscous_friction_fitted_is_covered():
    """Case (a) with friction='viscous': J_z and c covered, errors at the white value
    (measured 1.0-1.23 times it), no warning."""
    runs = _runs("viscous", friction="viscous")
    assert sum(abs(_z(r)) <= COVER_SIGMAS for r in runs) >= MIN_COVERED, [_z(r) for r in runs]
    zc = [
        (r.friction["viscous_friction"] - C_TRUE) / r.std_friction["viscous_friction"] for r in runs
    ]
    assert sum(abs(z) <= COVER_SIGMAS for z in zc) >= MIN_COVERED, zc
    assert all(
        r.std_friction["viscous_friction"] >= r.details["std_white_friction"]["viscous_friction"]
        for r in runs
    )
    assert not any(r.warnings for r in runs)


def test_missing_viscous_friction_is_widened_and_warned():
    """Case (a) with the default friction=None: the fitted terms absorb part of the missing
    torque, which no residual shows, so even the widened error (measured 9.5-12 times the
    white one) leaves the truth 3.2-4.2 sigmas off (white: 38-40). What the answer owes the
    user is then the warning naming the missing torque and the remedy."""
    runs = _runs("viscous")
    z = np.array([_z(r) for r in runs])
    assert np.all(np.abs(z) < 6), z  # a regression of the sandwich would leave it near 40
    assert all(r.std_inertia > 5 * r.std_white[0] for r in runs)
    assert all(any("friction='viscous'" in w for w in r.warnings) for r in runs)


# ------------------------------------------------ dof-1 spin-down (output error), the same pair


def _spin_down(seed: int, coloured: bool) -> tuple:
    """60 s spin-down of a passive yaw platform from 3 rad/s with a known viscous friction
    2e-4 N m s (J_z 0.036 kg m^2, seed-004 sensors: gyro 7.7e-4 rad/s at 20 Hz)."""
    import dataclasses

    from airbearing.analysis.simulation.artefacts import sample_times
    from airbearing.analysis.simulation.on_times import simulate_on_times
    from airbearing.io.testbed import Body

    tb = load_testbed("seed004-platform")
    tb = tb.replace(
        body=Body(dof=1, mass=tb.body.mass, inertia=0.036), masses=None, magnetorquers=None,
        field=None, sensors=dataclasses.replace(tb.sensors, attitude_noise=0.0),
        effects={"viscous_friction": 2e-4},
    )  # fmt: skip
    log = simulate_on_times(tb, sample_times(tb, 60.0), initial_rate=(0, 0, 3.0), seed=seed)
    d = log.data.copy()
    if coloured:  # AR(1) 0.95 gyro noise as large as the white
        rng = np.random.default_rng(50 + seed)
        sg, phi = tb.sensors.gyro_noise, 0.95
        u = rng.normal(0.0, sg * math.sqrt(1 - phi**2), len(d))
        d["wz"] = d["wz"] + lfilter([1.0], [1.0, -phi], u, zi=[phi * rng.normal(0.0, sg)])[0]
    return tb, Log(d, source=f"spin-{seed}.csv", testbed=tb)


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_spin_down_output_error_keeps_both_errors():
    """Output error reports the engine's sandwich beside its Fisher value: equal within the
    HAC's sampling error on white noise (measured 1.00-1.09 over 40 seeds), wider under
    AR(1) gyro noise, where the Fisher value left 4 of 10 seeds beyond 3 sigmas. There the
    exact ratio (the linearised fit's variance under the simulated noise covariance,
    tests/shooting/test_shooting_errors.py) is 3.50 and 3.57 on seeds 0 and 1: the sandwich
    said 1.76 and 1.54 while its bandwidth ended at the residual's 1/e lag, and its old upper limit
    of 3.0 stood below the exact value; now 4.10 and 3.28 (2.4-4.8 over 40 seeds)."""
    from airbearing.analysis.identification.yaw_inertia import identify_yaw_inertia

    for coloured, lo, hi in ((False, 1.0, 1.15), (True, 2.5, 5.0)):
        for seed in (0, 1):
            tb, log = _spin_down(seed, coloured)
            res = identify_yaw_inertia(tb, [log])
            assert res.method == "output-error"
            ratio = res.std_inertia / res.std_white[0]
            assert lo <= ratio <= hi, (coloured, seed, ratio)
            assert res.to_json()["std_white"] == pytest.approx(res.std_white[0])
