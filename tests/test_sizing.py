"""Flywheel sizing: seed 001 eqs. 5-9 reproduce Table 5; bad input is refused."""

import json
import math
import re

import pytest
from cli_run import run

import airbearing.cli.cmg  # noqa: F401  (registers `airbearing cmg` before the lead wires it)
from airbearing.design.sizing import size_cluster
from airbearing.errors import InputError

TABLE5 = {"angle": math.radians(30.0), "time": 2.0, "inertia": 0.0033}  # seed 001 Table 5


def test_table5_reproduced_to_the_printed_digits():
    r = size_cluster(**TABLE5)
    # seed 001 Table 5, compared at the digits the paper prints
    assert f"{r.torque * 1e3:.3f}" == "1.728"  # N_req, mNm
    assert f"{r.momentum * 1e3:.4f}" == "0.8661"  # h0, mNms
    assert f"{r.flywheel_inertia * 1e3:.6f}" == "0.002068"  # I_f, g m^2
    assert f"{r.flywheel_mass * 1e3:.1f}" == "14.1"  # m_f, g
    assert f"{r.flywheel_thickness * 1e3:.1f}" == "5.8"  # L_f, mm


def test_torque_scales_as_eq5():
    a = size_cluster(**TABLE5)
    b = size_cluster(TABLE5["angle"], 2 * TABLE5["time"], 2 * TABLE5["inertia"])
    # eq. 5: N = J a / (t/2)^2, so doubling J and t halves N; eqs. 7-9 are linear in N
    assert b.torque == pytest.approx(a.torque / 2, rel=1e-14)
    assert b.flywheel_thickness == pytest.approx(a.flywheel_thickness / 2, rel=1e-14)


@pytest.mark.parametrize(
    "change",
    [
        {"time": -2.0},
        {"time": 0.0},
        {"angle": 0.0},
        {"inertia": -1e-3},
        {"skew": 0.0},
        {"skew": math.pi / 2},
        {"flywheel_speed": 0.0},
        {"flywheel_speed": -10.0},
        {"inner_radius": 0.02},
        {"density": float("nan")},
    ],
    ids=["negative-time", "zero-time", "zero-angle", "negative-inertia", "skew-0", "skew-90",
         "zero-speed", "negative-speed", "inner-beyond-outer", "nan-density"],
)  # fmt: skip
def test_bad_input_raises(change):
    with pytest.raises(InputError):
        size_cluster(**{**TABLE5, **change})


def test_cli_size_json(tmp_path, capsys):
    out = tmp_path / "size.json"
    rc = run(["cmg", "size", "--angle-deg", "30", "--time", "2", "--inertia", "0.0033",
              "--json", str(out)])  # fmt: skip
    assert rc == 0
    d = json.loads(out.read_text())
    # seed 001 Table 5 at its printed digits
    assert round(d["torque_nm"] * 1e3, 3) == 1.728
    assert round(d["momentum_nms"] * 1e3, 4) == 0.8661
    assert round(d["flywheel_inertia_kgm2"] * 1e6, 3) == 2.068
    assert round(d["flywheel_mass_kg"] * 1e3, 1) == 14.1
    assert round(d["flywheel_thickness_m"] * 1e3, 1) == 5.8
    # the terminal table: seed 001 Table 5's torque, in mN m
    assert re.search(r"required torque N_req\s+1\.728\s+mN m", capsys.readouterr().out)


@pytest.mark.parametrize(
    "extra",
    [["--skew-deg", "0"], ["--skew-deg", "90"], ["--flywheel-rpm", "0"], ["--time", "-1"]],
    ids=["skew-0", "skew-90", "zero-rpm", "negative-time"],
)
def test_cli_size_bad_input_exit_2_no_file(tmp_path, capsys, extra):
    out = tmp_path / "size.json"
    args = ["cmg", "size", "--angle-deg", "30", "--time", "2", "--inertia", "0.0033"]
    rc = run(args + extra + ["--json", str(out)])
    assert rc == 2
    assert not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("airbearing: error:")
