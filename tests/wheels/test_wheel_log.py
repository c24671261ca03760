"""Logs of reaction-wheel testbeds: ws/wc columns, outliers, saturation, import units,
simulated logs (FORMATS.md, "Log" and "Import map")."""

import math

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose

import airbearing as ab
from airbearing.api.logs import check_log
from airbearing.errors import InputError
from airbearing.io.log import Log, wheel_saturation
from airbearing.io.log_import import import_log_with_notes
from airbearing.io.quality import assess
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model

RW3 = "rw-3axis"


def _wheel_log(name="rw-yaw", n=400, seed=0):
    """A torque-driven run of the built-in simulated with its sensors' noise (NumPy)."""
    tb = load_testbed(name)
    m = build_model(tb)
    rng = np.random.default_rng(seed)
    k = tb.wheels.n
    U = np.zeros((m.nu, n))
    wc = m.index([f"wc{i}" for i in range(1, k + 1)], "u")
    U[wc] = np.repeat(rng.uniform(-8e-4, 8e-4, (k, n // 40)), 40, axis=1)
    x0 = m.x0(wheels=np.full(k, 50.0))
    X = np.vstack([x0, np.asarray(m.rollout(n, tb.sensors.dt)(x0, U, m.p0)).T])[:-1]
    Y = np.asarray(m.h(X.T, U, m.p0)).T
    cols = {"t": tb.sensors.dt * np.arange(n)}
    for i, name_y in enumerate(m.y_names):
        if name_y.startswith("ws"):
            cols[name_y] = Y[:, i] + rng.normal(scale=tb.wheels.speed_noise, size=n)
        elif name_y in ("yaw", "wz", "qw", "qx", "qy", "qz", "wx", "wy"):
            cols[name_y] = Y[:, i]
    for i, j in enumerate(wc):
        cols[f"wc{i + 1}"] = U[j]
    return tb, pd.DataFrame(cols)


def test_wheel_columns_are_read_and_exposed():
    tb, df = _wheel_log(RW3)
    log = Log(df, testbed=tb)
    assert log.wheel_speeds().shape == (len(df), 4)
    assert_allclose(log.wheel_commands(), df[["wc1", "wc2", "wc3", "wc4"]].to_numpy())


@pytest.mark.parametrize(
    ("change", "parts"),
    [
        (lambda d: d.assign(ws5=0.0), ["column 'ws5'", "has 4 reaction wheel(s)", "ws1 .. ws4"]),
        (lambda d: d.assign(wc5=0.0), ["column 'wc5'", "has 4 reaction wheel(s)"]),
        (lambda d: d.drop(columns=["wc3"]), ["missing column 'wc3'", "all or none"]),
        (lambda d: d.drop(columns=["ws2"]), ["missing column 'ws2'"]),
    ],
    ids=["extra-ws", "extra-wc", "missing-wc", "missing-ws"],
)
def test_wheel_column_count_must_match_the_testbed(change, parts):
    tb, df = _wheel_log(RW3, n=40)
    with pytest.raises(InputError) as e:
        Log(change(df), "run.csv", tb)
    message = str(e.value)
    assert message.startswith("run.csv: ") and "\n" not in message
    for part in parts:
        assert part in message, message


def test_wheel_columns_on_a_testbed_without_wheels():
    tb = load_testbed("seed004-platform")
    df = pd.DataFrame({"t": [0.0, 0.05], "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0,
                       "wx": 0.0, "wy": 0.0, "wz": 0.0, "s1": 0.0, "s2": 0.0, "s3": 0.0,
                       "ws1": 0.0})  # fmt: skip
    with pytest.raises(InputError, match=r"column 'ws1': .* has 0 reaction wheel\(s\)"):
        Log(df, "run.csv", tb)


def test_a_wheel_speed_spike_is_an_outlier():
    tb, df = _wheel_log()
    df.loc[150, "ws1"] += 40 * tb.wheels.speed_noise  # 40 noise scales
    q = assess(Log(df, testbed=tb), tb)
    assert q.outlier_rows == (150,)
    assert q.outliers[0].columns == ("ws1",)
    # the robust scale measures the logged noise (0.01 rad/s): within 20 % on 400 samples
    assert q.noise["ws1"] == pytest.approx(tb.wheels.speed_noise, rel=0.2)


def test_saturated_commands_are_reported_not_clipped():
    tb, df = _wheel_log(n=80)
    df.loc[[10, 11, 12, 40], "wc1"] = [2e-3, -1.5e-3, 1.001e-3, 5e-3]
    log = Log(df.copy(), testbed=tb)
    (sat,) = wheel_saturation(log)
    assert sat["column"] == "wc1" and sat["rows"] == [10, 11, 12, 40]
    assert sat["limit"] == tb.wheels.max_torque and sat["largest"] == 5e-3
    assert "10-12, 40" in sat["reason"] and "saturated" in sat["reason"]
    assert_allclose(log.column("wc1"), df["wc1"])  # kept as logged
    check = check_log(log)
    assert check.to_json()["wheel_saturation"][0]["rows"] == [10, 11, 12, 40]
    # replay and the fits take wheel logs with their wheel speeds, and say so without
    assert check.tools["replay"][0] and check.tools["discrepancy"][0]


def test_import_map_knows_rpm_and_mN_m(tmp_path):
    tb = load_testbed("rw-yaw")
    raw = pd.DataFrame(
        {"time": [0.0, 0.05, 0.1], "yaw": 0.0, "rate": 0.0,
         "speed rpm": [0.0, 600.0, -6000.0], "torque mNm": [0.0, 0.5, -1.0]}
    )  # fmt: skip
    mapping = {
        "columns": {"t": "time", "yaw": "yaw", "wz": "rate", "ws1": "speed rpm",
                    "wc1": "torque mNm"},
        "units": {"ws1": "rpm", "wc1": "mN m"},
    }  # fmt: skip
    log = import_log_with_notes(raw, mapping, tb).log
    assert_allclose(log.column("ws1"), [0.0, 20 * math.pi, -200 * math.pi], rtol=1e-15)
    assert_allclose(log.column("wc1"), [0.0, 5e-4, -1e-3], rtol=1e-15)
    mapping["units"]["wc1"] = "rpm"  # a speed unit for a torque command
    with pytest.raises(InputError, match=r"key 'units.wc1': expected a torque unit"):
        import_log_with_notes(raw, mapping, tb)
    mapping["units"]["wc1"] = "kg"
    with pytest.raises(InputError, match=r"key 'units.wc1'.* one of N m, mN m, rad/s"):
        import_log_with_notes(raw, mapping, tb)


def test_simulated_wheel_log_has_ws_and_wc():
    tb = load_testbed("rw-yaw").with_effects({"wheel_viscous_friction": 1e-6})
    wheels = tb.wheels
    tb = tb.replace(wheels=type(wheels)(**{**wheels.__dict__, "speeds": (300.0,)}))
    run = ab.free_oscillation(tb, duration=5.0, noise=False)
    data = run.log.data
    assert {"ws1", "wc1", "true_W1"} <= set(data.columns)
    assert np.all(data["wc1"] == 0.0)
    # noise-free: the logged speed is the state; it decays (viscous) from 300 rad/s
    assert_allclose(data["ws1"], data["true_W1"], rtol=0, atol=0)
    J, Iw = tb.body.yaw_inertia, wheels.inertia[0]
    rate = 1e-6 * J / (Iw * (J - Iw))  # models/wheels.py: viscous spin-down, body free
    # RK4 at 20 Hz with rate x dt = 2e-3: error far below 1e-9
    assert_allclose(data["ws1"], 300.0 * np.exp(-rate * data["t"]), rtol=1e-9)


def test_speed_command_steps_are_not_outliers():
    # a speed-commanded wheel follows each step of wc within a few samples (tau = 0.1 s at
    # 20 Hz): a kink at a command switch, which the outlier search must not flag
    tb = load_testbed("rw-yaw")
    w = tb.wheels
    tb = tb.replace(wheels=type(w)(axes=w.axes, inertia=w.inertia, max_torque=w.max_torque,
                                   max_speed=w.max_speed, command="speed", speed_loop_tau=0.1,
                                   speed_noise=0.01))  # fmt: skip
    m = build_model(tb)
    rng = np.random.default_rng(2)
    n = 600
    U = np.zeros((m.nu, n))
    U[m.index("wc1", "u")] = np.repeat(rng.uniform(-300, 300, n // 60), 60)
    X = np.vstack([m.x0(), np.asarray(m.rollout(n, tb.sensors.dt)(m.x0(), U, m.p0)).T])[:-1]
    Y = np.asarray(m.h(X.T, U, m.p0)).T
    noise = rng.normal(size=(n, 3)) * [1.7e-3, 3.86e-4, 0.01]
    df = pd.DataFrame({"t": tb.sensors.dt * np.arange(n), "yaw": Y[:, 0] + noise[:, 0],
                       "wz": Y[:, 1] + noise[:, 1], "ws1": Y[:, 2] + noise[:, 2],
                       "wc1": U[m.index("wc1", "u")[0]]})  # fmt: skip
    q = assess(Log(df, testbed=tb), tb)
    assert q.outlier_rows == () and q.discontinuities == ()


def test_log_check_and_plot_show_the_wheels(tmp_path, capsys):
    from cli_run import run

    tb, df = _wheel_log(RW3, n=200)
    df.loc[[5, 6], "wc2"] = -3e-3
    path = tmp_path / "wheels.csv"
    df.to_csv(path, index=False)
    assert run(["log", "check", RW3, str(path), "--json", str(tmp_path / "c.json")]) == 0
    out = capsys.readouterr().out
    assert "wheels    4: speeds ws1..ws4" in out and "torque commands wc1..wc4 (N m)" in out
    assert "wc2 beyond wheels.max_torque = 0.001 N m in 2 row(s) (5-6" in out
    from airbearing.reporting.log_plot import log_figure

    fig = log_figure(Log(df, testbed=tb))
    panels = {ax.get_title(loc="left"): ax for ax in fig.axes}
    speeds, commands = panels["wheel speeds"], panels["wheel commands"]
    assert [ln.get_label() for ln in speeds.lines] == ["ws1", "ws2", "ws3", "ws4"]
    assert commands.get_ylabel() == "torque command (mN m)"
    # plotted in rpm and mN m
    assert_allclose(speeds.lines[0].get_ydata(), df["ws1"] * 60 / (2 * math.pi), rtol=1e-12)
    assert_allclose(commands.lines[1].get_ydata(), df["wc2"] * 1e3, rtol=1e-12)


def test_simulate_takes_an_effect_value_per_wheel(tmp_path, capsys):
    # FORMATS.md: a wheel_* effect is a number or one value per wheel (four on rw-3axis)
    from cli_run import run

    out = tmp_path / "w.csv"
    value = "wheel_torque_error=0.05,-0.05,0,0"
    assert run(["simulate", RW3, "--duration", "2", "--effect", value, "--out", str(out)]) == 0
    assert out.exists()
    capsys.readouterr()
    bad = tmp_path / "bad.csv"
    args = ["simulate", RW3, "--duration", "2", "--effect", "wheel_torque_error=0.05,-0.05,0"]
    assert run([*args, "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "wheel_torque_error" in err and "4 numbers (one per wheel)" in err
    assert not bad.exists()
