"""``airbearing simulate --attitude-only``: a closed-loop slew filmed by motion capture.

The slew's loop flies on the testbed's gyro; the log holds what a camera sees: the true
attitude plus white noise of ``--attitude-noise`` (default ``sensors.attitude_noise``) and
no rate columns, with the gyro-less testbed to read it (``--write-testbed``). A testbed
file without a gyro is refused for a slew unless the option is given; bad input is one
error line, exit 2, nothing written.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from scipy import stats
from statsmodels.stats.diagnostic import acorr_ljungbox

from airbearing import quaternion as quat
from airbearing.io.testbed import load_testbed, read_testbed, write_testbed

LEVEL = 0.001  # test level of the noise checks: a correct log fails one in a thousand runs
RATES = {"wx", "wy", "wz", "gx", "gy", "gz"}


def _white_at(e: np.ndarray, sigma: float) -> tuple[float, float]:
    """p-values that ``e`` is white noise of 1-sigma ``sigma``: chi-square of its variance
    (two-sided) and Ljung-Box of its first 10 lags."""
    chi2 = float(np.sum(e**2) / sigma**2)
    p_var = 2 * min(stats.chi2.sf(chi2, e.size), stats.chi2.cdf(chi2, e.size))
    p_lb = float(acorr_ljungbox(e, lags=[10])["lb_pvalue"].iloc[0])
    return p_var, p_lb


@pytest.mark.parametrize("noise", [None, 5e-3])
def test_the_log_has_the_camera_s_attitude_and_no_rate(tmp_path, monkeypatch, noise):
    monkeypatch.chdir(tmp_path)
    args = ["simulate", "rw-yaw", "--attitude-only", "--duration", "20", "--noise-seed", "2"]
    args += [] if noise is None else ["--attitude-noise", str(noise)]
    rc = run([*args, "-o", "mocap.csv", "--json", "s.json", "--write-testbed", "mocap.toml"])
    assert rc == 0
    sigma = load_testbed("rw-yaw").sensors.attitude_noise if noise is None else noise
    d = pd.read_csv("mocap.csv")
    assert not RATES & set(d.columns)
    assert {"yaw", "ws1", "wc1", "true_yaw"} <= set(d.columns)
    e = d["yaw"].to_numpy() - d["true_yaw"].to_numpy()
    p_var, p_lb = _white_at(e, sigma)  # 400 samples: the level, white (not a gyro's walk)
    assert p_var > LEVEL and p_lb > LEVEL, (p_var, p_lb)
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["log"] == "attitude_only"
    assert summary["attitude_noise"] == sigma
    assert summary["loop_gyro_noise"] == load_testbed("rw-yaw").sensors.gyro_noise
    tb = read_testbed(tmp_path / "mocap.toml")
    assert not tb.sensors.gyro and tb.sensors.attitude_noise == sigma


def test_a_three_axis_log_turns_the_true_attitude_by_the_camera_s_noise(tmp_path, monkeypatch):
    # cmg-3dof (CMGs, dof 3): the attitude is q_true (x) exp(n), n white of --attitude-noise
    monkeypatch.chdir(tmp_path)
    args = ["simulate", "cmg-3dof", "--attitude-only", "--yaw-deg", "30", "--duration", "10"]
    assert run([*args, "--attitude-noise", "2e-3", "-o", "m.csv"]) == 0
    d = pd.read_csv("m.csv")
    assert not RATES & set(d.columns)
    q = d[["qw", "qx", "qy", "qz"]].to_numpy()
    q_true = d[[f"true_{k}" for k in ("qw", "qx", "qy", "qz")]].to_numpy()
    dq = quat.qmul(quat.qconj(q_true), q)
    n = 2 * dq[:, 1:] * np.sign(dq[:, :1])  # the vector part of exp(n) is n / 2, |n| << 1
    p_var, p_lb = _white_at(n.ravel(), 2e-3)
    assert p_var > LEVEL and p_lb > LEVEL, (p_var, p_lb)


def _gyroless(tmp_path):
    tb = load_testbed("rw-yaw")
    path = tmp_path / "rig.toml"
    write_testbed(tb.replace(sensors=dataclasses.replace(tb.sensors, gyro=False)), path)
    return path


def test_a_gyroless_testbed_slews_only_with_the_option(tmp_path, monkeypatch, capsys):
    rig = _gyroless(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert run(["simulate", str(rig), "--duration", "2", "-o", "a.csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--attitude-only" in err[0] and "sensors.gyro = false" in err[0]
    assert not (tmp_path / "a.csv").exists()
    assert run(["simulate", str(rig), "--attitude-only", "--duration", "2", "-o", "a.csv"]) == 0
    assert not RATES & set(pd.read_csv("a.csv").columns)


def test_a_gyroless_file_without_gyro_noise_flies_a_noise_free_gyro_and_says_so(
    tmp_path, monkeypatch
):
    tb = load_testbed("rw-yaw")
    rig = tmp_path / "rig.toml"
    write_testbed(
        tb.replace(sensors=dataclasses.replace(tb.sensors, gyro=False, gyro_noise=0.0)), rig
    )
    monkeypatch.chdir(tmp_path)
    args = ["simulate", str(rig), "--attitude-only", "--duration", "2", "--json", "s.json"]
    assert run(args) == 0
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["loop_gyro_noise"] == 0.0
    assert any("noise-free gyro" in w for w in summary["warnings"]), summary


BAD = [
    (["--attitude-only", "--attitude-noise", "-1"], "--attitude-noise -1"),
    (["--attitude-only", "--attitude-noise", "nan"], "--attitude-noise"),
    (["--attitude-noise", "1e-3"], "--attitude-noise"),  # a slew without the option
    (["--write-testbed", "t.toml"], "--write-testbed"),  # nothing gyro-less to write
    (["--attitude-only", "--write-testbed", "t.json"], "--write-testbed t.json"),
    (["--attitude-only", "--scenario", "free"], "--attitude-only"),
    (["--attitude-only", "--scenario", "spindown"], "--attitude-only"),
]


@pytest.mark.parametrize(("extra", "named"), BAD)
def test_bad_input_is_one_error_exit_2_and_nothing_written(
    tmp_path, monkeypatch, capsys, extra, named
):
    monkeypatch.chdir(tmp_path)
    args = ["simulate", "rw-yaw", "--duration", "2", "-o", "a.csv", "--json", "a.json", *extra]
    assert run(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0], err
    assert list(tmp_path.iterdir()) == []
