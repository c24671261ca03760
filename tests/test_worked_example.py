"""The README's worked example, end to end: a lab's raw motion-capture file to named effects.

The raw file is made here the way a lab's exporter writes it (millisecond clock, yaw in
degrees wrapped to +-180, a frame counter, a recording gap, a marker swap and an occluded
frame) from a coast-down simulated by the package, so the answer is known: viscous friction
and aerodynamic drag, 3.5e-5 each (the size of a CubeSat mock-up's measured spin-down,
decel/J = 7e-4 w + 7e-4 w^2). Then exactly the README's commands: log import, log check,
discrepancy, replay of the augmented testbed.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from rigs import MOCAP_MAP_TOML, MOCAP_RIG_TOML

# the README's motion-capture rig and its import map
MAP, RIG = MOCAP_MAP_TOML, MOCAP_RIG_TOML

TRUTH = {"aero_drag": 3.5e-5, "viscous_friction": 3.5e-5}


@pytest.mark.slow
def test_raw_motion_capture_file_to_named_effects(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rig.toml").write_text(RIG)
    (tmp_path / "map.toml").write_text(MAP)
    # the truth: a 4 rad/s coast-down, 20 s unlogged from t = 100 s, two glitched frames
    args = ["--quiet", "simulate", "rig.toml", "--scenario", "spindown", "--spin-rate", "4"]
    args += ["--duration", "260", "--gap", "100:20", "--seed", "3"]
    args += ["--glitch", "yaw_offset:400", "--glitch", "yaw_zero:1700"]
    for name, value in TRUTH.items():
        args += ["--effect", f"{name}={value}"]
    assert run([*args, "-o", "sim.csv", "--json", "key.json"]) == 0
    key = json.loads((tmp_path / "key.json").read_text())
    sim = pd.read_csv(tmp_path / "sim.csv")
    # as the lab's exporter writes it
    yaw_deg = np.degrees(sim["yaw"].to_numpy())
    raw = pd.DataFrame(
        {
            "Frame": np.arange(len(sim)),
            "Time (ms)": np.round(sim["t"].to_numpy() * 1000.0, 3),
            "Yaw (deg)": (yaw_deg + 180.0) % 360.0 - 180.0,
        }
    )
    raw.to_csv(tmp_path / "raw.csv", index=False)

    # the README's four steps
    assert run(["--quiet", "log", "import", "raw.csv", "--map", "map.toml", "--testbed",
                "rig.toml", "-o", "spin.csv"]) == 0  # fmt: skip
    assert run(["--quiet", "log", "check", "spin.csv", "--testbed", "rig.toml", "--json",
                "check.json"]) == 0  # fmt: skip
    check = json.loads((tmp_path / "check.json").read_text())
    assert check["segments"] == key["segments"] == 2
    assert check["outlier_rows"] == key["outlier_rows"] == [400, 1700]
    assert run(["--quiet", "discrepancy", "rig.toml", "spin.csv", "--json", "d.json",
                "--write-testbed", "rig+.toml"]) == 0  # fmt: skip
    result = json.loads((tmp_path / "d.json").read_text())
    named = {e["name"]: e for e in result["effects"]}
    assert set(named) == set(TRUTH), result["verdict"]
    for name, value in TRUTH.items():
        # issue 13: the hidden effects named within 20 %; and the value honest: >= 3 std
        assert abs(named[name]["value"] - value) <= 0.2 * value, (name, named[name])
        assert abs(named[name]["value"]) >= 3 * named[name]["std"]
    assert result["gap_unit"] == "rad" and result["outlier_rows"] == [400, 1700]
    assert run(["--quiet", "replay", "rig+.toml", "spin.csv", "--json", "r.json"]) == 0
    replay = json.loads((tmp_path / "r.json").read_text())
    # a correct model replays to about the noise floor (README: "~1.0 x the floor")
    assert replay["gap"] <= 1.5 * replay["noise_floor"], replay
