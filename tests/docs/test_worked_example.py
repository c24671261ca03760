"""The README's worked example, end to end: a lab's raw motion-capture file to named effects.

Exactly the commands of the README's worked-example block, run in a temporary folder with a
copy of ``examples/`` as in a fresh clone, in-process (``airbearing``'s ``main``: each new
interpreter paid ~3 s of imports; the process boundary is tested by the CLI's own tests).
The raw files there were made by ``examples/mocap-spin/make_raw.py`` from coast-downs
simulated by the package, so the answer is known: viscous friction and aerodynamic drag,
3.5e-5 each (the size of a CubeSat mock-up's measured spin-down, decel/J = 7e-4 w + 7e-4
w^2), a 20 s gap, a marker swap at row 400 and an occluded frame at row 1700. A second test
checks that the committed files are what that script makes (so the answer key above is the
files' own).
"""

from __future__ import annotations

import importlib.util
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cli_run import run
from test_readme_commands import TEXT, worked_example_commands

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "mocap-spin"


def _make_raw():
    spec = importlib.util.spec_from_file_location("make_raw", EXAMPLE / "make_raw.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_readme_worked_example_names_the_hidden_effects(tmp_path, monkeypatch, capsys):
    truth = _make_raw().TRUTH
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    commands = worked_example_commands(TEXT)
    assert [c[:2] for c in commands] == [["log", "import"], ["log", "check"], ["discrepancy",
        "examples/mocap-spin/rig.toml"], ["log", "import"], ["replay", "rig+.toml"]]  # fmt: skip
    for args in commands:
        code = run(["--quiet", *args])
        assert code == 0, f"airbearing {' '.join(args)}: {capsys.readouterr().err[-1500:]}"
    check = json.loads((tmp_path / "check.json").read_text())
    assert check["segments"] == 2 and check["outlier_rows"] == [400, 1700]
    result = json.loads((tmp_path / "d.json").read_text())
    named = {e["name"]: e for e in result["effects"]}
    assert set(named) == set(truth), result["verdict"]
    for name, value in truth.items():
        # named within 20 % (the noise is 1 mrad on a 2400-row log), and >= 3 std from zero
        assert abs(named[name]["value"] - value) <= 0.2 * value, (name, named[name])
        assert abs(named[name]["value"]) >= 3 * named[name]["std"]
    assert result["gap_unit"] == "rad" and result["outlier_rows"] == [400, 1700]
    # the README says so: nothing on the rig acts that does not scale with J
    status = {c["name"]: c["status"] for c in result["candidates"]}
    assert status["inertia_error"].startswith("not identifiable"), status
    replay = json.loads((tmp_path / "r.json").read_text())
    # the augmented testbed on the second run: about the noise floor ("1.00 x" in the README)
    assert replay["gap"] <= 1.5 * replay["noise_floor"], replay


def test_committed_raw_files_are_what_make_raw_makes(tmp_path):
    _make_raw().main(tmp_path)
    for name in ("raw.csv", "raw2.csv"):
        made, kept = pd.read_csv(tmp_path / name), pd.read_csv(EXAMPLE / name)
        assert list(made.columns) == list(kept.columns) == ["Frame", "Time (ms)", "Yaw (deg)"]
        assert len(made) == len(kept)
        # written with 3 decimals of ms and 5 of degrees: equal to the last written digit
        assert np.allclose(made.to_numpy(), kept.to_numpy(), rtol=0, atol=2e-5), name
