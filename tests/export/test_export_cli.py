"""``airbearing export`` and ``simulate --gains``: the chain tune -> simulate -> export -> fly
as files, and bad input refused in one line with nothing written."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import get_args

import numpy as np
import pandas as pd
import pytest
from c_compiler import c_compiler
from cli_run import run

import airbearing as ab
from airbearing.analysis.simulation.scenarios import slew
from airbearing.cli import export as export_cli
from airbearing.design import export as export_lib
from airbearing.design.steering import STEERING_LAWS

TUNED = {"K_p": 3.0, "K_i": 0.002, "K_w": 4.0}
#: s, a short slew of the judged scenario (180 deg, ideal)
SLEW_S = "20"


def _gains_file(folder, loop="attitude", gains=TUNED):
    path = folder / f"{loop}_gains.json"
    path.write_text(json.dumps({"loop": loop, "gains": gains}))
    return path


def test_cli_choices_agree_with_the_library():
    assert set(get_args(export_cli.ExportLoop)) == set(export_lib.EXPORT_LOOPS)
    assert set(get_args(export_cli.Steering)) == set(STEERING_LAWS)
    assert set(get_args(export_cli.Method)) == set(export_lib.BALANCING_METHODS)


def test_simulate_gains_flies_the_file_gains(tmp_path):
    """A run with a gains file differs from the default and equals the same gains in Python."""
    gains = _gains_file(tmp_path)
    assert run(["simulate", "cmg-yaw", "--ideal", "--duration", "10", "--gains", str(gains),
                "-o", str(tmp_path / "tuned.parquet")]) == 0  # fmt: skip
    assert run(["simulate", "cmg-yaw", "--ideal", "--duration", "10",
                "-o", str(tmp_path / "seed.parquet")]) == 0  # fmt: skip
    tuned = pd.read_parquet(tmp_path / "tuned.parquet")
    seed = pd.read_parquet(tmp_path / "seed.parquet")
    py = slew(ab.load_testbed("cmg-yaw"), duration=10.0, ideal=True, gains=TUNED).log.data
    cols = ["dd1", "dd2", "dd3", "dd4", "true_yaw"]
    np.testing.assert_array_equal(tuned[cols].to_numpy(), py[cols].to_numpy())
    assert np.abs(tuned[cols].to_numpy() - seed[cols].to_numpy()).max() > 1e-3


def test_simulate_gains_refused_where_it_does_not_apply(tmp_path, capsys):
    gains = _gains_file(tmp_path)
    assert run(["simulate", "seed000-tabletop", "--gains", str(gains)]) == 2
    assert "--gains" in capsys.readouterr().err
    bad = _gains_file(tmp_path, gains={"K_p": 1.0})
    assert run(["simulate", "cmg-yaw", "--gains", str(bad), "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert "--gains" in err and "K_i" in err and len(err.strip().splitlines()) == 1
    other = _gains_file(tmp_path, "balancing", {"K_p": 1e-3, "K_d": 1e-3, "K_dK_i": 1e-5})
    assert run(["simulate", "cmg-yaw", "--gains", str(other)]) == 2
    assert not (tmp_path / "x.csv").exists()


def test_tune_simulate_export_check_chain(tmp_path, capsys):
    """The tutorial chain with a gains file: the export replays the run it was simulated with,
    through the CSV log (its digits are enough for 1e-9), and the harness runs."""
    cc = c_compiler()
    gains = _gains_file(tmp_path)
    log = tmp_path / "slew.csv"
    assert run(["simulate", "cmg-yaw", "--scenario", "slew", "--yaw-deg", "180", "--ideal",
                "--steering", "gsr", "--duration", SLEW_S, "--gains", str(gains),
                "-o", str(log)]) == 0  # fmt: skip
    out = tmp_path / "rig"
    capsys.readouterr()
    assert run(["export", "cmg-yaw", "--loop", "attitude", "--steering", "gsr",
                "--gains", str(gains), "--name", "yaw_ctl", "--harness", "--check", str(log),
                "-o", str(out)]) == 0  # fmt: skip
    said = capsys.readouterr().out
    assert "largest command difference" in said
    assert sorted(p.name for p in out.iterdir()) == [
        "yaw_ctl.c", "yaw_ctl.h", "yaw_ctl.json", "yaw_ctl_main.c"]  # fmt: skip
    meta = json.loads((out / "yaw_ctl.json").read_text())
    assert meta["gains"] == TUNED and meta["steering"] == "gsr" and meta["dt"] == 0.05
    assert meta["airbearing_version"] == ab.__version__
    # the bench harness: the log's y and r columns as CSV (with a header) in, commands out
    exe = tmp_path / "bench"
    subprocess.run([cc, "-std=c99", "-O2", str(out / "yaw_ctl.c"), str(out / "yaw_ctl_main.c"),
                    "-lm", "-o", str(exe)], check=True)  # fmt: skip
    data = pd.read_csv(log)
    cols = [e["name"] for e in meta["y"] + meta["r"]]
    proc = subprocess.run([str(exe)], input=data[cols].to_csv(index=False), text=True,
                          capture_output=True, check=True)  # fmt: skip
    got = np.loadtxt(proc.stdout.splitlines(), delimiter=",")
    want = data[[e["name"] for e in meta["u"]]].to_numpy()
    assert np.abs(got - want).max() <= 1e-9


def test_check_fails_with_exit_2_and_names_the_lowpass_variant(tmp_path, capsys):
    """A run with the gyro low-pass (simulate without --ideal) is not a run of the default
    export (the control law alone): exit 2, nothing written, and the fix named."""
    c_compiler()
    log = tmp_path / "rig.csv"
    assert run(["simulate", "cmg-yaw", "--scenario", "slew", "--yaw-deg", "90", "--duration",
                "5", "-o", str(log)]) == 0  # fmt: skip
    capsys.readouterr()
    assert run(["export", "cmg-yaw", "--loop", "attitude", "--check", str(log),
                "-o", str(tmp_path / "out")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "exceeds the bound" in err and "export with --lowpass" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["cmg-yaw", "--loop", "balancing"], "platform"),
        (["seed000-tabletop", "--loop", "attitude"], "kind = 'platform'"),
        (["cmg-yaw", "--loop", "attitude", "--name", "9lives"], "C identifier"),
        (["cmg-yaw", "--loop", "attitude", "--name", "int"], "C identifier"),
        (["cmg-yaw", "--loop", "attitude", "--name", "a-b"], "C identifier"),
        (["cmg-yaw", "--loop", "attitude", "--method", "mixed"], "--method"),
        (["seed000-tabletop", "--loop", "balancing", "--steering", "sr"], "--steering"),
        (["seed004-platform", "--loop", "balancing", "--method", "mixed"], "magnetorquers"),
    ],
)
def test_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, args, words):
    out = tmp_path / "out"
    assert run(["export", *args, "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    ("loop", "gains", "words"),
    [
        ("attitude", {"K_p": 1.0}, "do not fit the attitude loop"),
        ("attitude", {"K_p": 1.0, "K_i": 0.0, "K_w": -1.0}, "K_w"),
        ("balancing", {"K_p": 1e-3, "K_d": 1e-3, "K_dK_i": 1e-5}, "'loop' is 'balancing'"),
    ],
)
def test_gains_that_do_not_fit(tmp_path, capsys, loop, gains, words):
    path = _gains_file(tmp_path, loop, gains)
    out = tmp_path / "out"
    assert run(["export", "cmg-yaw", "--loop", "attitude", "--gains", str(path),
                "-o", str(out)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and words in err and "--gains" in err, err
    assert not out.exists()


def test_balancing_gains_file_reaches_the_law(tmp_path):
    gains = {"K_p": 2e-3, "K_d": 3e-3, "K_dK_i": 4e-5}
    path = _gains_file(tmp_path, "balancing", gains)
    out = tmp_path / "out"
    assert run(["export", "seed000-tabletop", "--loop", "balancing", "--gains", str(path),
                "--real", "float", "-o", str(out)]) == 0  # fmt: skip
    meta = json.loads((out / "balancing_mixed.json").read_text())
    assert meta["gains"] == gains and meta["real"] == "float" and meta["method"] == "mixed"
    assert [u["name"] for u in meta["u"]] == ["motor1", "motor2", "motor3", "mx", "my", "mz"]
    assert (
        "static const balancing_mixed_real balancing_mixed_gains[3] = {0.002, 0.003, 4e-05};"
        in (out / "balancing_mixed.c").read_text()
    )


def test_the_tutorial_chain_runs_as_written(tmp_path, monkeypatch):
    """The commands of the tutorial's "Tune, simulate, export, fly" step, verbatim, on a gains
    file like step 2's (tuning itself is tested with the tuner)."""
    c_compiler()
    page = Path(__file__).parents[2] / "docs" / "tutorials" / "slew-tune-report.md"
    section = page.read_text().split("## 4. Tune, simulate, export, fly", 1)[1]
    block = section.split("```sh", 1)[1].split("```", 1)[0]
    commands = [ln.split() for ln in block.strip().splitlines()]
    assert [c[1] for c in commands] == ["simulate", "export", "export"]
    monkeypatch.chdir(tmp_path)
    _gains_file(tmp_path).rename(tmp_path / "gains.json")
    for cmd in commands:
        assert cmd[0] == "airbearing"
        assert run(cmd[1:]) == 0, " ".join(cmd)
    assert (tmp_path / "rig" / "yaw_ctl_main.c").is_file()
    meta = json.loads((tmp_path / "rig" / "yaw_ctl.json").read_text())
    assert meta["real"] == "float" and meta["lowpass"] == 0.25 and meta["gains"] == TUNED
