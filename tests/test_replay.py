"""Replay of a log by a testbed's Model: inputs, noise floor, gap (analysis/replay.py)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from airbearing.analysis.discrepancy.replay import (
    make_windows,
    noise_floor,
    open_loop,
    replay,
    replay_data,
)
from airbearing.analysis.simulation.scenarios import free_oscillation, slew
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import Sensors, load_testbed
from airbearing.models.model import build_model

# seed-004 free oscillation (public example platform_viscous: initial state)
W0 = (0.3676, 0.1265, -1.4835)
Q0 = (0.99458, 0.024955, -0.014973, 0.099819)
SLIDERS = (0.003, -0.002, 0.004)


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
    # sliders held as logged (FORMATS.md: zero-order hold of the logged positions)
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
    w = open_loop(res.model, data)
    np.testing.assert_allclose(w, data.w, atol=5e-6)
    res = slew(cmg, ideal=True, duration=10.0)
    data = replay_data(cmg, res.log)
    w = open_loop(res.model, data)
    # seed 001 eq. 10 driven by the logged (commanded, held) gimbal rates
    np.testing.assert_allclose(w, data.w, atol=5e-6)


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
    if kind == "platform":
        # attitude noise 1e-3 rad per axis (the simulation's attitude_noise), 10 % allowed
        assert fl.attitude == pytest.approx(1e-3, rel=0.1)


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


def test_gap_is_the_rms_of_the_rate_residual(cmg):
    res = slew(cmg, seed=4, duration=20.0)
    rp = replay(cmg, res.log)
    r = rp.residuals()
    # module doc: gap = RMS over every used sample and axis of (w_meas - w_model)
    assert rp.gap == pytest.approx(float(np.sqrt(np.mean(r["residual"] ** 2))), rel=1e-9)
    assert len(r["t"]) == rp.windows.n * rp.windows.length


def test_windows_and_too_short_logs():
    w = make_windows(1200, 0.05)
    assert w.length == 200 and w.n == 6  # min(10 s, 60 s / 4) = 10 s = 200 samples
    with pytest.raises(InputError, match="too short"):
        make_windows(15, 0.05, source="short.csv")


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
    model = build_model(cmg)
    assert model.nu == data.u.shape[1]
