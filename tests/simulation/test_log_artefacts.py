"""Logs on given sample times and the artefact injectors (jitter, gaps, glitches, edges).

Oracles: the standard simulation on the same uniform grid (same arithmetic), scipy's
DOP853 on the same physics written here, and the definitions of each artefact.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp

from airbearing import quaternion as quat
from airbearing.analysis.simulation.artefacts import (
    GLITCH_KINDS,
    sample_times,
    segment_starts,
    with_first_sample_artefact,
    with_gap,
    with_glitches,
    with_jitter,
    with_last_sample_artefact,
    with_sign_flips,
)
from airbearing.analysis.simulation.on_times import integrate_on_times, simulate_on_times
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.errors import InputError
from airbearing.io.testbed import testbed_from_dict as make_testbed
from airbearing.models.model import build_model

# seed 004: the 6.3 kg platform, J_CR and offset r^o; seed 000: 0.041 kg sliders, 6e-4 T cage
J3 = np.array([[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]])
R3 = np.array([0.0004, 0.0007, -0.0026])
STATES3 = ["qw", "qx", "qy", "qz", "wx", "wy", "wz"]


def platform(*, masses=True, gyro=True, attitude_noise=1e-3):
    d = {
        "kind": "platform",
        "name": "seed004-like",
        "gravity": 9.81,
        "body": {"dof": 3, "mass": 6.3, "inertia": J3.tolist(), "cm_offset": R3.tolist()},
        "field": {"lab": [0.0, 0.0, 6e-4]},
        "sensors": {
            "rate": 20.0,
            "gyro_noise": 4e-4,
            "gyro": gyro,
            "attitude_noise": attitude_noise,
        },
    }
    if masses:
        d["masses"] = {
            "mass": [0.041] * 3,
            "axes": np.eye(3).tolist(),
            "travel": 0.037,
            "step": 2e-6,
            "speed": 0.005,
        }
        d["magnetorquers"] = {"max_dipole": 1.0}
    return make_testbed(d)


def yaw_rig(gyro=True):
    return make_testbed(
        {
            "kind": "platform",
            "name": "yaw-rig",
            "gravity": 9.81,
            "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
            "sensors": {"rate": 10.0, "gyro": gyro, "gyro_noise": 2e-4, "attitude_noise": 1e-3},
        }
    )


# ------------------------------------------------------------------------------ on times


@pytest.mark.parametrize("masses", [True, False])
def test_on_a_uniform_grid_it_is_the_standard_simulation(masses):
    tb = platform(masses=masses)
    effects = {"viscous_friction": 2e-5, "sensor_lag": 0.05}
    sliders = (0.003, -0.004, 0.002) if masses else (0.0, 0.0, 0.0)
    # both at 4 RK4 sub-steps per sample (the standard simulation's default chooses its own)
    ref = free_oscillation(
        tb, initial_rate=(-0.48, 0.09, -1.62), sliders=sliders, effects=effects,
        duration=20.0, noise=False, substeps=4,
    )  # fmt: skip
    inputs = dict(zip(("s1", "s2", "s3"), sliders, strict=True)) if masses else None
    log = simulate_on_times(tb, ref.t, x0=ref.x[0], effects=effects, inputs=inputs, noise=False)
    # the same RK4 arithmetic with dt an input instead of a constant: equal to rounding
    # (measured 4e-15); the brief asks ~1e-9
    for k in [*STATES3, "lag_wx"]:
        assert_allclose(log.column(f"true_{k}"), ref.log.column(f"true_{k}"), rtol=0, atol=1e-12)
    common = [c for c in ref.log.data.columns if c in log.data.columns]
    assert {"qw", "wx", "gx", "bx"} <= set(common)
    assert ("s1" in common) == masses and ("mx" in common) == masses
    for c in common:
        assert_allclose(log.column(c), ref.log.column(c), rtol=0, atol=1e-12)


def _rigid_body(t, x, c):
    """The physics written out: J w' + w x J w = m r x g_body - c w; q' = q (x) [0, w] / 2."""
    q, w = x[:4], x[4:]
    w0, w1, w2 = w
    qw, qx, qy, qz = q
    q_dot = 0.5 * np.array(
        [
            -qx * w0 - qy * w1 - qz * w2,
            qw * w0 + qy * w2 - qz * w1,
            qw * w1 + qz * w0 - qx * w2,
            qw * w2 + qx * w1 - qy * w0,
        ]
    )
    # body-frame gravity R^T [0, 0, -g]: minus g times the third row of R(q)
    g_body = -9.81 * np.array(
        [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)]
    )
    torque = 6.3 * np.cross(R3, g_body) - c * w
    w_dot = np.linalg.solve(J3, torque - np.cross(w, J3 @ w))
    return np.concatenate([q_dot, w_dot])


def test_jittered_times_with_a_gap_agree_with_dop853():
    tb = platform(masses=False)
    c = 2e-5
    t = with_jitter(sample_times(tb, 30.0), 0.3, seed=3)
    t, _ = with_gap(t, 10.0, 5.0)
    q0 = quat.qexp([0.03, -0.02, 0.9])
    x0 = np.concatenate([q0, [-0.48, 0.09, -1.62]])
    sol = solve_ivp(_rigid_body, (t[0], t[-1]), x0, "DOP853", t_eval=t, rtol=1e-12,
                    atol=1e-13, args=(c,))  # fmt: skip
    errors = {}
    for sub in (4, 8):
        model = build_model(tb, {"viscous_friction": c})
        X = integrate_on_times(model, t, x0, substeps=sub)
        errors[sub] = np.max(np.abs(X - sol.y.T))
    # RK4 at h <= 1.5 dt / 8 = 9.4 ms over 30 s of a 2.3 rad/s pendulum: measured 6.8e-8
    # (rates); DOP853 at rtol 1e-12 is 4 orders closer to the truth than that
    assert errors[8] < 2e-7
    # and the error is RK4's own: halving h divides it by 2^4 = 16 (measured 15.9)
    assert 12 < errors[4] / errors[8] < 20


def test_gap_is_integrated_through_not_jumped():
    """A 20 s gap: the motion continues during it (a recording gap, not a pause)."""
    tb = yaw_rig()
    t, after = with_gap(sample_times(tb, 60.0), 20.0, 20.0)
    log = simulate_on_times(
        tb, t, initial_rate=1.0, noise=False, effects={"viscous_friction": 5e-4}
    )
    # w = w0 exp(-c t / J) at every logged time, before and after the gap
    assert_allclose(log.column("true_wz"), np.exp(-5e-4 / 0.05 * t), rtol=1e-12)
    assert after == 200 and t[after] == pytest.approx(40.0)


def test_on_times_bad_input():
    tb = yaw_rig()
    with pytest.raises(InputError, match="row 2"):
        simulate_on_times(tb, [0.0, 0.1, 0.1, 0.2], initial_rate=1.0)
    with pytest.raises(InputError, match="row 1"):
        simulate_on_times(tb, [0.0, np.nan, 0.2], initial_rate=1.0)
    with pytest.raises(InputError, match="unknown input"):
        simulate_on_times(tb, [0.0, 0.1], inputs={"s9": 1.0})
    with pytest.raises(InputError, match="travel"):
        simulate_on_times(platform(), [0.0, 0.05], inputs={"s1": 0.05})
    with pytest.raises(InputError, match="not both"):  # nothing silently overridden
        simulate_on_times(tb, [0.0, 0.1], x0=[0.0, 1.0], initial_rate=2.0)
    with pytest.raises(InputError, match="yaw0"):
        simulate_on_times(tb, [0.0, 0.1], q0=[1.0, 0.0, 0.0, 0.0])


# ------------------------------------------------------------------------------ times


def test_jitter_keeps_each_interval_within_its_fraction():
    t = sample_times(yaw_rig(), 100.0)
    j = with_jitter(t, 0.4, seed=1)
    ratio = np.diff(j) / np.diff(t)
    assert np.all(np.abs(ratio - 1) <= 0.4) and j[0] == t[0]
    assert np.max(np.abs(ratio - 1)) > 0.3  # uniform draws reach near the bound
    assert np.max(np.abs(j - t)) <= 0.2 * 0.1 + 1e-15  # on the same clock: no drift
    assert_allclose(with_jitter(t, 0.4, seed=1), j, rtol=0, atol=0)
    assert not np.allclose(with_jitter(t, 0.4, seed=2), j)
    with pytest.raises(InputError, match="fraction"):
        with_jitter(t, 1.0)


def test_gap_removes_the_samples_in_its_window():
    t = sample_times(yaw_rig(), 10.0)
    g, row = with_gap(t, 3.0, 2.0)
    assert len(g) == len(t) - 20 and row == 30
    assert g[row - 1] == pytest.approx(2.9) and g[row] == pytest.approx(5.0)
    for bad in ((-1.0, 1.5), (9.5, 2.0), (3.01, 0.05)):
        with pytest.raises(InputError, match="gap"):
            with_gap(t, *bad)


# ------------------------------------------------------------------------------ glitches


@pytest.fixture(scope="module")
def gyro_log():
    tb = platform(masses=True)
    t = with_jitter(sample_times(tb, 30.0), 0.2, seed=7)
    return simulate_on_times(tb, t, initial_rate=(-0.48, 0.09, -1.62), seed=3,
                             inputs={"s1": 0.003, "s2": -0.004, "s3": 0.002})  # fmt: skip


def _changed(a, b):
    diff = a.data.to_numpy() != b.data.to_numpy()
    rows = tuple(int(i) for i in np.flatnonzero(diff.any(axis=1)))
    cols = {a.data.columns[j] for j in np.flatnonzero(diff.any(axis=0))}
    return rows, cols


@pytest.mark.parametrize(
    ("kind", "columns"),
    [
        ("rate_zero", {"wx", "wy", "wz"}),
        ("rate_spike", {"wz"}),
        ("quat_wrong_frame", {"qw", "qx", "qy", "qz"}),
        ("yaw_offset", {"qw", "qx", "qy", "qz"}),
        ("yaw_zero", {"qw", "qx", "qy", "qz"}),
    ],
)
def test_each_glitch_hits_exactly_its_rows_and_columns(gyro_log, kind, columns):
    glitched, rows = with_glitches(gyro_log, [594, 287], kind)
    assert rows == (287, 594)
    assert _changed(glitched, gyro_log) == (rows, columns)  # truth and other rows untouched
    a = gyro_log.data.loc[list(rows)]
    b = glitched.data.loc[list(rows)]
    if kind == "rate_zero":
        assert np.all(b[["wx", "wy", "wz"]].to_numpy() == 0)
    elif kind == "rate_spike":  # 20 gyro sigmas of 4e-4 rad/s (the raw examples' size)
        assert_allclose(b["wz"] - a["wz"], 20 * 4e-4, rtol=1e-9)
    else:
        q0 = a[["qw", "qx", "qy", "qz"]].to_numpy()
        q1 = b[["qw", "qx", "qy", "qz"]].to_numpy()
        turn = quat.qmul(q1, quat.qconj(q0))  # lab-side rotation from the clean attitude
        angle = 2 * np.arccos(np.minimum(1, np.abs(turn[:, 0])))
        if kind == "yaw_zero":
            assert np.all(q1 == [1, 0, 0, 0])
        else:
            expected = {"quat_wrong_frame": 90.0, "yaw_offset": 8.0}[kind]
            assert_allclose(np.rad2deg(angle), expected, rtol=1e-9)
            axis = turn[:, 1:] / np.sin(angle / 2)[:, None] * np.sign(turn[:, :1])
            assert_allclose(np.abs(axis), [[1, 0, 0]] * 2 if kind[0] == "q" else [[0, 0, 1]] * 2,
                            atol=1e-9)  # fmt: skip


def test_yaw_glitches_on_an_attitude_only_dof1_log():
    tb = yaw_rig(gyro=False)
    log = simulate_on_times(tb, sample_times(tb, 100.0), initial_rate=4.0, seed=1)
    g, rows = with_glitches(log, 613, "yaw_offset")
    assert rows == (613,)
    assert g.column("yaw")[613] - log.column("yaw")[613] == pytest.approx(np.deg2rad(8))
    g, rows = with_glitches(g, [100, 900], "yaw_zero")
    assert np.all(g.column("yaw")[[100, 900]] == 0)
    assert _changed(g, log) == ((100, 613, 900), {"yaw"})
    for kind in ("rate_zero", "rate_spike", "quat_wrong_frame"):  # nothing to hit
        with pytest.raises(InputError, match=kind):
            with_glitches(log, [5], kind)


def test_glitch_bad_input(gyro_log):
    for rows, match in (([10, 10], "twice"), ([gyro_log.n], "outside"), ([1.5], "integer")):
        with pytest.raises(InputError, match=match):
            with_glitches(gyro_log, rows, "rate_zero")
    with pytest.raises(InputError, match="expected one of"):
        with_glitches(gyro_log, [1], "rate_drift")
    with pytest.raises(InputError, match="no size"):
        with_glitches(gyro_log, [1], "rate_zero", size=1.0)
    with pytest.raises(InputError, match="no column"):
        with_glitches(gyro_log, [1], "yaw_offset", column="wx")
    assert set(GLITCH_KINDS) == {"rate_zero", "rate_spike", "quat_wrong_frame", "yaw_offset",
                                 "yaw_zero"}  # fmt: skip
    from airbearing.cli.simulate import GLITCHES  # the CLI's help lists the same kinds

    assert GLITCHES.split("|") == list(GLITCH_KINDS)


def test_first_sample_artefact_at_each_segment_start():
    tb = yaw_rig(gyro=True)
    t, after = with_gap(with_jitter(sample_times(tb, 100.0), 0.3, seed=4), 40.0, 15.0)
    log = simulate_on_times(tb, t, initial_rate=2.0, seed=2)
    assert segment_starts(log) == (0, after)
    g, rows = with_first_sample_artefact(log)
    assert rows == (0, after)
    assert _changed(g, log) == (rows, {"wz"})
    assert np.all(g.column("wz")[list(rows)] == 0)
    g, last = with_last_sample_artefact(log)
    assert last == (after - 1, log.n - 1) and _changed(g, log) == (last, {"wz"})
    with pytest.raises(InputError, match="wx, wy, wz"):
        with_first_sample_artefact(simulate_on_times(yaw_rig(gyro=False), t, initial_rate=2.0))


# ------------------------------------------------------------------------------ rehearsal


def test_rehearsal_log_and_its_answer_key(tmp_path):
    import json

    from cli_run import run

    from airbearing.analysis.simulation.rehearsal import parse_gap, parse_glitch, rehearsal_log
    from airbearing.io.log import read_log
    from airbearing.io.testbed import write_testbed

    tb = yaw_rig(gyro=True)
    r = rehearsal_log(
        tb, duration=100.0, initial_rate=(0, 0, 2.0), jitter=0.2, gaps=[(40.0, 15.0)],
        glitches=[parse_glitch("rate_spike:10,700"), ("yaw_zero", (300,))], first_sample=True,
        effects={"aero_drag": 1e-4}, seed=3,
    )  # fmt: skip
    key = r.to_json()
    # the clock jitters with seed + 1: the gap starts where with_gap says on those times
    t, after = with_gap(with_jitter(sample_times(tb, 100.0), 0.2, seed=4), 40.0, 15.0)
    assert_allclose(r.log.t, t, rtol=0, atol=0)
    assert key["segments"] == 2 and key["segment_rows"] == [[0, after], [after, len(t)]]
    assert key["first_sample_rows"] == [0, after]
    assert key["outlier_rows"] == [0, 10, 300, after, 700]
    assert parse_gap("150:20") == (150.0, 20.0)
    for bad in ("150", "a:b", "1:-2"):
        with pytest.raises(InputError, match="^gap '"):
            parse_gap(bad)
    with pytest.raises(InputError, match="KIND:ROW"):
        parse_glitch("rate_drift:4")
    assert parse_glitch("rate_spike:594@wy") == ("rate_spike", (594,), "wy")
    with pytest.raises(InputError, match="only rate_spike"):
        parse_glitch("rate_zero:4@wy")
    spiked = rehearsal_log(tb, times=r.log.t, glitches=[("rate_spike", (5,), "wz")])
    assert spiked.glitches == (("rate_spike", (5,)),)

    # the same through the CLI: the log and its answer key in the summary JSON
    path = write_testbed(tb, tmp_path / "rig.toml")
    log, js = tmp_path / "r.parquet", tmp_path / "r.json"
    assert run(["simulate", str(path), "--scenario", "spindown", "--duration", "100",
                "--jitter", "0.2", "--gap", "40:15", "--glitch", "rate_spike:10,700",
                "--glitch", "yaw_zero:300", "--first-sample-artefact", "--seed", "3",
                "--effect", "aero_drag=1e-4", "-o", str(log), "--json", str(js)]) == 0  # fmt: skip
    summary = json.loads(js.read_text())
    assert summary["outlier_rows"] == key["outlier_rows"]
    assert_allclose(read_log(log, tb).column("wz"), r.log.column("wz"), rtol=0, atol=1e-15)
    assert run(["simulate", "cmg-yaw", "--jitter", "0.1", "--json", str(tmp_path / "s.json")]) == 2
    assert not (tmp_path / "s.json").exists()
    # a twin of a lab's log on its own clock: same times, same segments, same outlier-free rows
    twin = tmp_path / "twin.csv"
    assert run(["simulate", str(path), "--scenario", "spindown", "--times", str(log),
                "-o", str(twin)]) == 0  # fmt: skip
    assert_allclose(read_log(twin, tb).t, r.log.t, rtol=0, atol=1e-12)
    assert rehearsal_log(tb, times=r.log.t).to_json()["segment_rows"] == key["segment_rows"]
    with pytest.raises(InputError, match="duration"):
        rehearsal_log(tb, times=r.log.t, duration=10.0)


def test_chunked_rollout_is_one_rollout(monkeypatch):
    """Logs are integrated chunk by chunk; the chunk size changes nothing (same arithmetic)."""
    from airbearing.analysis.simulation import on_times

    tb = platform(masses=False)
    t, _ = with_gap(with_jitter(sample_times(tb, 30.0), 0.3, seed=1), 10.0, 3.0)
    kw = {"initial_rate": (-0.48, 0.09, -1.62), "effects": {"sensor_lag": 0.05}, "seed": 2}
    whole = simulate_on_times(tb, t, **kw)  # 600 samples: one chunk
    monkeypatch.setattr(on_times, "CHUNK", 64)  # 10 chunks, the last one padded
    chunked = simulate_on_times(tb, t, **kw)
    for c in whole.data.columns:
        assert_allclose(chunked.column(c), whole.column(c), rtol=0, atol=0)


def test_disturbance_torque_is_white_per_interval():
    """J w' = tau_k held over each interval: w_(k+1) - w_k = tau_k dt_k / J exactly."""
    from scipy import stats

    tb = yaw_rig()
    sigma = 1e-4  # N m
    t = with_jitter(sample_times(tb, 200.0), 0.3, seed=6)
    log = simulate_on_times(tb, t, initial_rate=0.5, torque_noise=sigma, seed=3)
    tau = np.diff(log.column("true_wz")) * 0.05 / np.diff(t)
    n = tau.size
    # chi-square with n degrees of freedom, two-sided false-alarm probability 2e-6
    assert stats.chi2.ppf(1e-6, n) < np.sum((tau / sigma) ** 2) < stats.chi2.ppf(1 - 1e-6, n)
    quiet = simulate_on_times(tb, t, initial_rate=0.5, torque_noise=sigma, noise=False)
    assert np.all(quiet.column("true_wz") == 0.5)  # noise=False: no disturbance either


def test_sign_flips_keep_the_attitude(gyro_log):
    flipped, rows = with_sign_flips(gyro_log)  # the qw >= 0 hemisphere of many exporters
    assert rows == tuple(np.flatnonzero(gyro_log.column("qw") < 0))
    assert len(rows) > 0 and np.all(flipped.column("qw") >= 0)
    q0, q1 = gyro_log.quaternions(), flipped.quaternions()
    assert_allclose(quat.rotation_matrix(q1), quat.rotation_matrix(q0), rtol=0, atol=1e-15)
    assert _changed(flipped, gyro_log) == (rows, {"qw", "qx", "qy", "qz"})
    _, some = with_sign_flips(gyro_log, [3, 1])
    assert some == (1, 3)


@pytest.mark.slow
def test_long_logs_run_compiled_with_the_same_values(monkeypatch):
    """From LOOP_MIN_STEPS intervals on, compiled chunks (C) replace the virtual machine."""
    from airbearing.analysis.simulation import on_times

    tb = yaw_rig()
    t, _ = with_gap(with_jitter(sample_times(tb, 650.0), 0.3, seed=2), 300.0, 20.0)
    assert t.size >= on_times.LOOP_MIN_STEPS
    kw = {"initial_rate": 4.0, "effects": {"aero_drag": 3.5e-5}, "seed": 1}
    fast = simulate_on_times(tb, t, **kw)
    monkeypatch.setattr(on_times, "LOOP_MIN_STEPS", 10**9)  # force the virtual machine
    slow = simulate_on_times(tb, t, **kw)
    for c in fast.data.columns:  # the same operations; C and the VM may round differently
        assert_allclose(fast.column(c), slow.column(c), rtol=1e-12, atol=1e-12)
