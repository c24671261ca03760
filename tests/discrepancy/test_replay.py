"""Replay of logs by a testbed's Model: inputs, segments, outliers, noise floor, gap.

Oracles: the simulator (the same physics, integrated independently on the logged
times by ``simulate_on_times``) and the configured noise levels of the simulated
sensors (derivable: a correct model leaves the noise).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

# seed-004 free oscillation, the mocap rotor and sphere, the jittered platform log
from rigs import Q0, ROTOR, SLIDERS, SPHERE, W0
from rigs import jittered_platform as _jittered_platform

from airbearing.analysis.discrepancy.replay import open_loop, replay
from airbearing.analysis.shooting import logs
from airbearing.analysis.shooting.logs import make_windows, noise_floor, replay_data
from airbearing.analysis.simulation.artefacts import (
    sample_times,
    with_gap,
    with_glitches,
    with_jitter,
)
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.analysis.simulation.scenarios import free_oscillation, slew, spindown
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import Sensors, load_testbed
from airbearing.models.model import build_model


@pytest.fixture(scope="module")
def platform():
    return load_testbed("platform-3dof")


@pytest.fixture(scope="module")
def cmg():
    tb = load_testbed("cmg-yaw")
    return tb.replace(sensors=Sensors(rate=tb.sensors.rate, gyro_noise=5e-4, lowpass=1.0))


def _free(tb, **kw):
    kw.setdefault("duration", 20.0)
    return free_oscillation(tb, initial_rate=W0, q0=Q0, sliders=SLIDERS, **kw)


def test_inputs_are_the_logged_ones_and_the_field_is_lab_frame(platform):
    res = _free(platform, seed=1, attitude_noise=1e-3)
    data = replay_data(platform, res.log)
    np.testing.assert_array_equal(data.u[:, 0:3], res.log.sliders())
    # the log's bx, by, bz are the lab field in body axes: rotated back with the measured
    # attitude and averaged, they give the testbed's lab field (seed 000 Sec. 3: 6e-4 T, up);
    # tolerance: attitude noise 1e-3 rad averages over 400 samples to < 1e-4 relative
    b_lab = data.u[:, [data.u_names.index(n) for n in ("bx_lab", "by_lab", "bz_lab")]]
    np.testing.assert_allclose(b_lab, np.tile(platform.field.lab_vec, (data.n, 1)), atol=6e-8)


def test_open_loop_replay_reproduces_a_noise_free_run(platform, cmg):
    # the simulator and the replay integrate the same Model with the same inputs; the
    # replay uses 2 RK4 sub-steps, the simulator 4: for rates up to 1.5 rad/s at 20 Hz the
    # difference is O(h^4) ~ 1e-6 rad/s over 10 s (RK4 error constant, seed-004 motion)
    res = _free(platform, duration=10.0, noise=False)
    data = replay_data(platform, res.log)
    np.testing.assert_allclose(open_loop(res.model, data), data.w, atol=5e-6)
    res = slew(cmg, ideal=True, duration=10.0)
    data = replay_data(cmg, res.log)
    # seed 001 eq. 10 driven by the logged (commanded, held) gimbal rates
    np.testing.assert_allclose(open_loop(res.model, data), data.w, atol=5e-6)


def test_open_loop_follows_jittered_times(platform):
    # simulate_on_times integrates on the jittered times (4 sub-steps per interval); the
    # replay takes each logged interval as its step: same O(h^4) bound as above
    log = simulate_on_times(
        platform,
        with_jitter(sample_times(platform, 10.0), 0.3, seed=3),
        initial_rate=W0,
        q0=Q0,
        inputs={"s1": SLIDERS[0], "s2": SLIDERS[1], "s3": SLIDERS[2]},
        noise=False,
    )
    data = replay_data(platform, log)
    np.testing.assert_allclose(open_loop(build_model(platform), data), data.w, atol=5e-6)


@pytest.mark.parametrize(
    "kind, sigma, tol",
    [
        # gyro noise of the built-in platform (XSens MTi-1 datasheet, 3.86e-4 rad/s);
        # MAD of 4800 fourth differences: ~2 % standard error, 6 % allowed
        ("platform", 3.86e-4, 0.06),
        # public examples' CMG gyro (5e-4 rad/s); the slew's abrupt gimbal-rate changes bias
        # a difference-based estimate up: 12 % allowed
        ("cmg", 5e-4, 0.12),
    ],
    ids=["platform", "cmg"],
)
def test_noise_floor_recovers_the_gyro_noise(platform, cmg, kind, sigma, tol):
    if kind == "platform":
        res = _free(platform, seed=2, attitude_noise=1e-3, duration=30.0)
        tb = platform
    else:
        res = slew(cmg, seed=2)
        tb = cmg
    fl = noise_floor(replay_data(tb, res.log))
    assert fl.rate == pytest.approx(sigma, rel=tol)
    assert fl.gap_unit == "rad/s"
    if kind == "platform":
        # attitude noise 1e-3 rad per axis (the simulation's attitude_noise), 10 % allowed
        assert fl.attitude == pytest.approx(1e-3, rel=0.1)


def test_noise_floor_on_jittered_times(platform):
    # +-20 % jitter: a plain fourth difference of a 1.5 rad/s oscillation would see
    # w' x 0.01 s ~ 1e-2 rad/s; the divided difference on the logged times does not.
    # 600 samples: MAD standard error ~4 %, 12 % allowed
    fl = noise_floor(replay_data(platform, _jittered_platform(platform, 5)))
    assert fl.rate == pytest.approx(platform.sensors.gyro_noise, rel=0.12)


@pytest.mark.parametrize("tb", [ROTOR, SPHERE], ids=["yaw", "quaternion"])
def test_noise_floor_of_an_attitude_only_log(tb):
    # the testbed's attitude_noise (1e-3 rad per axis) is the simulated motion-capture
    # noise; ~2000-2400 divided differences: ~3 % standard error of a MAD, 10 % allowed
    res = spindown(tb, initial_rate=3.0, duration=200.0 if tb.body.dof == 1 else 120.0, seed=4)
    data = replay_data(tb, res.log)
    assert data.w is None and data.gap_unit == "rad"
    fl = noise_floor(data)
    assert fl.rate is None
    assert fl.attitude == pytest.approx(1e-3, rel=0.1)
    assert fl.value == fl.attitude and fl.to_json()["gap_unit"] == "rad"


@pytest.mark.parametrize("kind", ["platform", "cmg"])
def test_correct_model_replays_to_the_noise_floor(platform, cmg, kind):
    if kind == "platform":
        tb, res = platform, _free(platform, seed=3, attitude_noise=1e-3, duration=20.0)
    else:
        tb, res = cmg, slew(cmg, seed=3)
    rp = replay(tb, res.log)
    # with the true model the residual is the gyro noise: gap = sigma sqrt(1 - n_free/n_res)
    # ~ sigma; the floor is estimated independently (within ~8 %), so 0.85..1.1
    assert 0.85 < rp.gap / rp.floor.rate < 1.1
    if kind == "cmg":
        # ... and an inertia 10 % off is far above it (seed 001: 0.00283 vs 0.00323 kg m^2)
        wrong = replay(tb, res.log, effects={"inertia_error": 0.1})
        assert wrong.gap > 5 * rp.floor.rate


@pytest.mark.slow
def test_attitude_only_replay_to_the_noise_floor_with_a_gap():
    # passive rotor coasting under viscous friction, 10 Hz motion capture, a 20 s gap
    t, _ = with_gap(sample_times(ROTOR, 160.0), 60.0, 20.0)
    eff = {"viscous_friction": 1e-4}
    log = simulate_on_times(ROTOR, t, initial_rate=3.0, effects=eff, seed=8)
    rp = replay(ROTOR.with_effects(eff), log)
    doc = rp.to_json()
    assert doc["gap_unit"] == "rad" and doc["segments"] == 2
    assert 0.85 < rp.gap / rp.floor.value < 1.1  # as above, in rad
    # the nominal model (no friction) misses a 3 rad/s coast-down by far
    assert replay(ROTOR, log).gap > 5 * rp.floor.value


def test_windows_never_span_a_gap_and_start_at_usable_rows(platform):
    log = _jittered_platform(platform, 6, gap=(12.0, 3.0))
    log, rows = with_glitches(log, [40, 101, 300], "rate_zero")
    data = replay_data(platform, log)
    assert len(data.segments) == 2  # FORMATS.md: an interval > 1.5 / rate splits the log
    assert set(rows) <= set(data.outlier_rows)
    w = make_windows(data, window_s=4.0)
    for j in range(w.n):
        used = w.rows[j][w.weight[j] > 0]
        seg = [(a, b) for a, b in data.segments if a <= used[0] < b]
        assert len(seg) == 1 and used[-1] < seg[0][1]  # inside one segment
        assert data.mask[w.rows[j, 0]]  # starts at a usable row
        assert not set(used) & set(data.outlier_rows)  # outliers weigh zero
        # the logged intervals are the integration steps
        m = int(w.weight[j].sum()) if data.mask[w.rows[j]].all() else None
        if m:
            np.testing.assert_allclose(w.dt[j, : m - 1], np.diff(data.t[w.rows[j, :m]]))


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_outliers_and_gaps_do_not_move_the_gap(platform):
    clean = _jittered_platform(platform, 7, gap=(12.0, 3.0))
    dirty, rows = with_glitches(clean, [50, 200, 420], "rate_spike", size=0.05)
    a, b = replay(platform, clean), replay(platform, dirty)
    doc = b.to_json()
    assert doc["logs"][0]["outlier_rows"] == sorted(rows)
    assert doc["segments"] == 2 and doc["gap_unit"] == "rad/s"
    # three 130-sigma spikes left out: the gap moves by the three samples' share only
    # (~3 / 1100 of the residual), 5 % allowed; kept in, they would triple it
    assert b.gap == pytest.approx(a.gap, rel=0.05)
    assert b.gap < 1.15 * b.floor.rate


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_several_logs_each_start_afresh(platform):
    logs = [_jittered_platform(platform, s, duration=15.0) for s in (11, 12)]
    rp = replay(platform, logs)
    doc = rp.to_json()
    assert len(doc["logs"]) == 2 and doc["segments"] == 2
    assert set(rp.windows.source) == {0, 1}
    for g in rp.log_gaps():
        assert 0.8 < g / rp.floor.rate < 1.2


def test_gap_is_the_rms_of_the_rate_residual(cmg):
    res = slew(cmg, seed=4, duration=20.0)
    rp = replay(cmg, res.log)
    r = rp.residuals()
    # module doc: gap = RMS over every usable sample and axis of (w_meas - w_model)
    assert rp.gap == pytest.approx(float(np.sqrt(np.mean(r["residual"] ** 2))), rel=1e-9)
    assert len(r["t"]) == int(rp.windows.weight.sum())


def test_windows_and_too_short_logs(cmg):
    res = slew(cmg, seed=0, duration=60.0)
    w = make_windows(replay_data(cmg, res.log))
    # min(10 s, 60 s / 4) = 10 s: 6 windows of 10 s at the 20 Hz of cmg-yaw
    assert w.length == 200 and w.n == 6
    short = Log(res.log.data.iloc[:15].reset_index(drop=True), "short.csv", cmg)
    with pytest.raises(InputError, match="too short"):
        make_windows(replay_data(cmg, short))


def test_linked_pieces_keep_their_length_on_long_logs(platform, cmg, monkeypatch):
    # logs.MAX_PIECES: pieces stay PIECE_S long where the attitude is measured however long
    # the log; a dof-1 gyro log (its start yaws profiled densely) keeps at most MAX_PIECES.
    # The cap lowered to 4 stands for a log longer than MAX_PIECES pieces (40 min).
    monkeypatch.setattr(logs, "MAX_PIECES", 4)
    osc = replay_data(platform, _free(platform, duration=60.0, seed=0).log)
    w = make_windows(osc, linked=True)
    # (a linked window also holds the next one's first row, where it hands over: ``end``)
    assert w.n == 6 and w.end[0] == round(logs.PIECE_S * platform.sensors.rate)
    gyro = replay_data(cmg, slew(cmg, seed=0, duration=60.0).log)
    assert gyro.outputs == ("rate",)
    w = make_windows(gyro, linked=True)
    assert w.n == 4 and w.end[0] == round(15.0 * cmg.sensors.rate)


def test_log_that_does_not_fit_the_testbed_kind(platform, cmg):
    res = slew(cmg, seed=0, duration=5.0)
    with pytest.raises(InputError, match="missing column"):
        replay_data(platform, res.log)  # a CMG log has no attitude quaternion, no sliders
    short = Log(res.log.data.iloc[:12].reset_index(drop=True), "short.csv", cmg)
    with pytest.raises(InputError, match="too short"):
        replay(cmg, short)


def test_missing_gimbal_rates_are_differenced(cmg):
    res = slew(cmg, ideal=True, duration=5.0)
    df = res.log.data.drop(columns=["dd1", "dd2", "dd3", "dd4"])
    data = replay_data(cmg, Log(pd.DataFrame(df), "no_dd.csv", cmg))
    # forward difference of the measured angles = the held commanded rate (ZOH, ideal run)
    np.testing.assert_allclose(
        data.input("dd1")[:-1], res.log.column("dd1")[:-1], rtol=1e-9, atol=1e-9
    )
    assert any("forward differences" in n for n in data.notes)
    assert build_model(cmg).nu == data.u.shape[1]


def test_a_single_log_gap_is_the_replay_gap_after_coloured_noise_is_estimated(platform):
    # the replay's fit is white; its process-noise estimate then sets a coloured measurement
    # noise on the problem: a log's gap must still unwhiten the fit's residual as it was made
    res = _free(platform, seed=3, attitude_noise=1e-3, effects={"viscous_friction": 2e-4})
    rp = replay(platform, res.log)
    assert rp.problem.measurement_noise is not None  # the case this test is about
    assert rp.log_gaps() == [rp.gap]
    assert rp.to_json()["logs"][0]["gap"] == rp.gap
