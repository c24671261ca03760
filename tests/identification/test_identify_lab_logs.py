"""Identification on logs as real testbeds write them (issue 13 items 2-4, 6; issue 12 item 6).

Oracles: the truth that generated each simulated log (seed 004 x_true, FORMATS.md
effects), the rows where artefacts were injected (returned by the injectors), and the
answer on the same motion without artefacts. Logs are simulated on their own sample
times (jitter, gaps) by ``simulate_on_times``, independently of the identification's
rollout.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from airbearing.analysis.identification.platform import (
    SEED004_TRUTH,
    identify_platform,
    seed004_testbed,
)
from airbearing.analysis.identification.yaw_inertia import identify_yaw_inertia
from airbearing.analysis.simulation.artefacts import (
    sample_times,
    with_first_sample_artefact,
    with_gap,
    with_glitches,
    with_jitter,
)
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.errors import InputError
from airbearing.io.testbed import Body, load_testbed

TRUTH = np.array(SEED004_TRUTH)
RUNS = [
    ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),  # seed 004's initial rate
    ((0.3676, 0.1265, -1.4835), (-0.020, 0.006, 0.024)),  # seed 004's experiment
    ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
]
#: Agreement in combined sigmas: 7 free parameters per comparison; P(|z| > 4) = 6.3e-5
#: each under the Gaussian errors the Fisher matrix states.
Z_TOL = 4.0


def _prior(tb):
    """The truth with every inertia entry 10 % off (the identification's start)."""
    J = tb.body.inertia_matrix * np.where(np.eye(3) > 0, 1.10, 0.90)
    return tb.replace(
        body=Body(dof=3, mass=tb.body.mass, inertia=tuple(map(tuple, J)), cm_offset=(0, 0, -2e-3))
    )


def _logs(tb, *, artefacts: bool, seed0: int, duration=20.0):
    """Three free oscillations; with artefacts: 20 % jitter, a 3 s gap, first-sample rate 0
    in each segment, a rate spike and a quaternion in the wrong frame (all rows returned)."""
    logs, hit = [], []
    for i, (w, s) in enumerate(RUNS):
        t = sample_times(tb, duration)
        if artefacts:
            t = with_jitter(t, 0.2, seed=seed0 + i)
            t, _ = with_gap(t, 8.0 + i, 3.0)
        inputs = {"s1": s[0], "s2": s[1], "s3": s[2]} if tb.masses is not None else None
        log = simulate_on_times(
            tb, t, initial_rate=w, inputs=inputs, seed=seed0 + 10 + i, attitude_noise=1e-3
        )
        rows: set = set()
        if artefacts:
            if tb.sensors.gyro:
                log, r = with_first_sample_artefact(log)
                rows |= set(r)
                log, r = with_glitches(log, [50 + 7 * i], "rate_spike")
                rows |= set(r)
            log, r = with_glitches(log, [250 + 3 * i], "quat_wrong_frame")
            rows |= set(r)
        logs.append(log)
        hit.append(sorted(rows))
    return logs, hit


def _z(a, b):
    """Difference of two independent estimates in combined sigmas (free parameters)."""
    ok = np.isfinite(a.std) & np.isfinite(b.std)
    return (a.theta - b.theta)[ok] / np.hypot(a.std, b.std)[ok]


@pytest.fixture(scope="module")
def truth():
    return seed004_testbed()


@pytest.fixture(scope="module")
def clean_and_artefacts(truth):
    clean, _ = _logs(truth, artefacts=False, seed0=100)
    dirty, hit = _logs(truth, artefacts=True, seed0=200)
    return clean, dirty, hit


# ---------------------------------------------------------------------------- artefacts


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_artefacts_equation_error(truth, clean_and_artefacts):
    """Gaps, jitter, glitches and first-sample artefacts: segments and outlier rows are
    reported exactly as injected, and the answer agrees with the clean log's within 4
    combined sigmas (plus the trapezoid bias, 5e-3 of the principal inertias, which
    differs between a jittered and a uniform grid)."""
    clean, dirty, hit = clean_and_artefacts
    prior = _prior(truth)
    a = identify_platform(prior, clean, known_offset_xy=TRUTH[6:8], method="equation-error")
    b = identify_platform(prior, dirty, known_offset_xy=TRUTH[6:8], method="equation-error")
    assert a.segments == 3 and b.segments == 6  # one gap per log
    assert b.outlier_rows == hit
    assert [lg["segments"] for lg in b.to_json()["logs"]] == [2, 2, 2]
    bias = 5e-3 * np.r_[TRUTH[:3], np.zeros(6)]
    ok = np.isfinite(a.std)
    tol = Z_TOL * np.hypot(a.std, b.std)[ok] + bias[ok]
    assert np.all(np.abs(a.theta - b.theta)[ok] < tol)


@pytest.mark.slow
def test_artefacts_output_error(truth, clean_and_artefacts):
    """Output error (jittered steps, each segment its own initial state, outliers masked):
    the answer with artefacts agrees with the clean one within 4 combined sigmas, and
    both with x_true within 4 of their own sigmas."""
    clean, dirty, hit = clean_and_artefacts
    prior = _prior(truth)
    a = identify_platform(prior, clean, known_offset_xy=TRUTH[6:8])
    b = identify_platform(prior, dirty, known_offset_xy=TRUTH[6:8])
    assert b.outlier_rows == hit and b.segments == 6
    assert len(b.details["initial_states"]) == 6  # one initial state per segment
    assert np.all(np.abs(_z(a, b)) < Z_TOL), _z(a, b)
    for res in (a, b):
        ok = np.isfinite(res.std)
        assert np.all(np.abs((res.theta - TRUTH)[ok] / res.std[ok]) < Z_TOL)
        assert res.details["ipopt_status"] == "Solve_Succeeded"
    # the masked rows matter: the rate spike alone is 20 gyro sigmas
    assert b.residual_rms < 1.5 * truth.sensors.gyro_noise


# ---------------------------------------------------------------------------- attitude only


def _attitude_only(tb):
    sensors = dataclasses.replace(tb.sensors, gyro=False, gyro_noise=0.0, attitude_noise=1e-3)
    return tb.replace(sensors=sensors)


@pytest.mark.slow
def test_attitude_only_recovers_the_truth(truth):
    """Motion capture only (sensors.gyro = false, 1 mrad): the output error on the attitude
    recovers every entry within 4 of its sigmas; residual in rad at the attitude noise
    (within 10 %: 3 x 400 samples of 3 axes give a 1.7 % spread); the glitch is left out."""
    tb = _attitude_only(truth)
    logs, hit = _logs(tb, artefacts=True, seed0=300)
    res = identify_platform(_prior(tb), logs, known_offset_xy=TRUTH[6:8])
    js = res.to_json()
    assert js["residual_unit"] == "rad" and js["equation_error"]["residual_unit"] == "N m s"
    assert res.residual_rms == pytest.approx(1e-3, rel=0.1)
    assert res.outlier_rows == hit and res.segments == 6
    assert all(lg["rates"] == "from attitude" for lg in js["logs"])
    ok = np.isfinite(res.std)
    assert ok.sum() == 7
    z = (res.theta - TRUTH)[ok] / res.std[ok]
    assert np.all(np.abs(z) < Z_TOL), z
    assert any("smooth differentiation" in w for w in res.equation_error.warnings)


def test_attitude_only_equation_error_start(truth):
    """The equation-error start from differentiated attitude: principal inertias within 2 %
    (seed 004's worst case), which is what the output-error stage needs to converge."""
    tb = _attitude_only(truth)
    logs, _ = _logs(tb, artefacts=False, seed0=400)
    res = identify_platform(_prior(tb), logs, known_offset_xy=TRUTH[6:8], method="equation-error")
    np.testing.assert_allclose(np.diag(res.inertia), TRUTH[:3], rtol=0.02)


# ---------------------------------------------------------------------------- passive


@pytest.fixture(scope="module")
def passive():
    return seed004_testbed().replace(masses=None, magnetorquers=None)


def test_passive_platform_needs_something_known(passive):
    """No sliders, no dipole, no known offset: J and r only up to a common scale
    (J w' + w x J w = m r x g is homogeneous): no number, the ratios and the fixes."""
    logs, _ = _logs(passive, artefacts=False, seed0=500, duration=10)
    assert not logs[0].has("s1")
    res = identify_platform(passive, logs, method="equation-error")
    assert not res.identifiable and np.all(np.isnan(res.theta))
    assert "common scale" in res.scale_free["reason"]


@pytest.mark.slow
def test_passive_platform_with_known_offset(passive):
    """A passive platform (no [masses]) with its in-plane offset known: every free entry
    within 4 output-error sigmas of the truth."""
    logs, _ = _logs(passive, artefacts=False, seed0=600)
    res = identify_platform(_prior(passive), logs, known_offset_xy=TRUTH[6:8])
    ok = np.isfinite(res.std)
    assert ok.sum() == 7
    z = (res.theta - TRUTH)[ok] / res.std[ok]
    assert np.all(np.abs(z) < Z_TOL), z


# ---------------------------------------------------------------------------- dof 1


def _yaw_testbed(effects=None, gyro=True):
    tb = load_testbed("seed004-platform")
    sensors = dataclasses.replace(tb.sensors, gyro=gyro, attitude_noise=0.0 if gyro else 1e-3)
    return tb.replace(
        body=Body(dof=1, mass=tb.body.mass, inertia=0.036),
        masses=None,
        magnetorquers=None,
        field=None,
        sensors=sensors,
        effects=effects or {},
    )


def _spindown(truth, seed=3):
    t, _ = with_gap(sample_times(truth, 120.0), 50.0, 20.0)
    return simulate_on_times(truth, t, initial_rate=(0, 0, 3.0), seed=seed)


def test_dof1_without_known_torque_is_not_identifiable():
    """A passive yaw rotor with nothing known acting: J_z is 'not identifiable from this
    log' with the reason, NaN (JSON null) instead of a number."""
    truth = _yaw_testbed()
    res = identify_yaw_inertia(truth, [_spindown(truth)])  # output error: never reached
    assert np.isnan(res.inertia) and np.isnan(res.std)
    assert res.std_status["J_zz"].startswith("not identifiable from this log: nothing")
    text = json.dumps(res.to_json(), allow_nan=True)
    assert "J_zz" in text
    with pytest.raises(InputError, match="not identifiable"):
        res.to_testbed(truth)


@pytest.mark.parametrize("effects", [{"viscous_friction": 2e-4}, {"aero_drag": 1e-4}])
def test_dof1_spindown_with_known_torque(effects):
    """Known friction (FORMATS.md units) in the testbed file: J_z of a gappy spin-down with
    first-sample artefacts within 4 of its sigmas of the truth 0.036 kg m^2, starting from
    a testbed 11 % off (0.04); the artefacts are reported and left out."""
    truth = _yaw_testbed(effects)
    log, rows = with_first_sample_artefact(_spindown(truth))
    nominal = truth.replace(body=Body(dof=1, mass=truth.body.mass, inertia=0.04))
    res = identify_yaw_inertia(nominal, [log], method="equation-error")
    assert res.segments == 2 and res.to_json()["outlier_rows"] == list(rows)
    assert abs(res.inertia - 0.036) < Z_TOL * res.std
    assert res.std < 0.02 * 0.036  # a tight check: 2 % per sigma at most


def test_dof1_attitude_only():
    """Yaw from motion capture only (1 mrad): rates by smooth differentiation; J_z within
    4 of its (larger) sigmas."""
    truth = _yaw_testbed({"viscous_friction": 2e-4}, gyro=False)
    log = _spindown(truth, seed=4)
    assert not log.has("wz")
    res = identify_yaw_inertia(truth, [log], method="equation-error")
    assert abs(res.inertia - 0.036) < Z_TOL * res.std
    assert res.std_status["J_zz"] == "estimated"


@pytest.mark.slow
@pytest.mark.parametrize("gyro", [True, False], ids=["gyro", "attitude-only"])
def test_dof1_output_error_on_the_shooting_engine(gyro):
    """Output error (the one shooting engine, J_z free): within 4 of its sigmas of the
    truth, its sigma well below the equation error's (the whole trajectory, not window
    ends, carries the information), residual at the sensor noise in the right unit."""
    truth = _yaw_testbed({"viscous_friction": 2e-4}, gyro=gyro)
    log = _spindown(truth, seed=4)
    if gyro:
        log, _ = with_first_sample_artefact(log)
    nominal = truth.replace(body=Body(dof=1, mass=truth.body.mass, inertia=0.04))
    ee = identify_yaw_inertia(nominal, [log], method="equation-error")
    res = identify_yaw_inertia(nominal, [log])
    assert res.method == "output-error" and res.std_status["J_zz"] == "estimated"
    assert abs(res.inertia - 0.036) < Z_TOL * res.std
    assert res.std < 0.2 * ee.std
    noise = truth.sensors.gyro_noise if gyro else truth.sensors.attitude_noise
    assert res.residual_unit == ("rad/s" if gyro else "rad")
    assert res.residual_rms == pytest.approx(noise, rel=0.1)  # 2000 samples: 3 % spread
