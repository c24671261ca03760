"""The command line: outputs, exit status 2 and one line for bad input, no partial files."""

import json
import subprocess
import sys

import pytest
from cli_run import run

from airbearing.io.log import read_log
from airbearing.io.testbed import load_testbed


def test_simulate_slew_writes_log_and_summary(tmp_path):
    log, js = tmp_path / "log.csv", tmp_path / "summary.json"
    rc = run(
        [
            "simulate",
            "cmg-yaw",
            "--scenario",
            "slew",
            "--yaw-deg",
            "180",
            "--ideal",
            "-o",
            str(log),
            "--json",
            str(js),
        ]
    )
    assert rc == 0
    s = json.loads(js.read_text())
    for key in (
        "peak_rate_deg_s",
        "t_peak_s",
        "gimbal_min_deg",
        "gimbal_final_deg",
        "final_yaw_error_deg",
    ):
        assert key in s
    assert len(s["gimbal_min_deg"]) == 4 and len(s["gimbal_final_deg"]) == 4
    assert s["peak_rate_deg_s"] == pytest.approx(51.38, rel=0.03)  # seed 001 Sec. 5
    read_log(log, load_testbed("cmg-yaw"))


def test_simulate_free_with_effect(tmp_path):
    out = tmp_path / "free.parquet"
    rc = run(
        [
            "simulate",
            "platform-3dof",
            "--scenario",
            "free",
            "--initial-rate",
            "0.3",
            "0.1",
            "-1.4",
            "--sliders",
            "0.003",
            "-0.002",
            "0.004",
            "--effect",
            "viscous_friction=6e-6",
            "--duration",
            "5",
            "--seed",
            "3",
            "-o",
            str(out),
        ]
    )
    assert rc == 0
    log = read_log(out, load_testbed("platform-3dof"))
    assert log.data["s1"].iloc[0] == pytest.approx(0.003)


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["simulate", "no-such-testbed"], "built-in"),
        (["simulate", "cmg-yaw", "--scenario", "wobble"], "--scenario"),
        (["simulate", "cmg-yaw", "--effect", "magic=1"], "unknown effect"),
        (["simulate", "cmg-yaw", "--effect", "viscous_friction"], "NAME=VALUE"),
        (["simulate", "cmg-yaw", "--duration", "-1"], "--duration"),
        (["simulate", "cmg-yaw", "--duration", "abc"], "--duration"),
        (["simulate", "platform-3dof", "--scenario", "slew"], "cmg"),
        (["simulate", "platform-3dof", "--scenario", "free", "--sliders", "1", "0", "0"], "travel"),
        (["simulate", "cmg-yaw", "--steering", "nope"], "--steering"),
    ],
    ids=[
        "unknown-testbed",
        "scenario",
        "effect-name",
        "effect-syntax",
        "negative-duration",
        "non-number",
        "platform-slew",
        "slider-travel",
        "steering",
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, args, fragment):
    out = tmp_path / "never.csv"
    rc = run([*args, "-o", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert fragment in err
    assert len(err.splitlines()) == 1
    assert not out.exists()


def test_console_script_has_no_traceback(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            "from airbearing.cli import main; main()",
            "simulate",
            str(tmp_path / "missing.toml"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_demo_quick(tmp_path):
    assert run(["demo", "--out", str(tmp_path), "--quick"]) == 0
    html = (tmp_path / "report.html").read_text()
    assert "Seed 001" in html and "data:image/svg+xml;base64," in html
