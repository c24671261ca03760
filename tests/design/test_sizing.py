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


# --- feasibility: what the sized cluster holds when the manoeuvre needs its peak momentum -----

BETA = math.radians(54.73)  # seed 001 Table 6
RATE = math.radians(35.0)  # seed 001 Table 5


def test_table5_cluster_holds_93_9_percent_at_t_half():
    """Bang-bang (eq. 5, Fig. 9): peak body rate 2a/t = 30 deg/s at t/2 = 1 s, body momentum
    J w = 1.728 mN m s (N_req times 1 s). At 35 deg/s the gimbals are at 35 deg then; eq. 7's
    torque 4 rate h0 cos(delta) sin(beta), integrated over that second (quadrature, not the
    closed form), is the momentum the cluster gave: 1.622 mN m s. With h0 from eq. 7 at 0 deg
    the share is sin(x)/x, x = 35 deg in rad (derivation in airbearing.design.sizing)."""
    from scipy.integrate import quad

    r = size_cluster(**TABLE5)
    h0 = r.momentum
    given, _ = quad(lambda t: 4 * RATE * h0 * math.cos(RATE * t) * math.sin(BETA), 0, 1.0)
    assert r.cluster_momentum == pytest.approx(given, rel=1e-12)
    assert r.cluster_momentum * 1e3 == pytest.approx(1.622, abs=5e-4)  # the reviewer's number
    assert r.peak_body_rate == pytest.approx(math.radians(30.0), rel=1e-14)
    assert r.momentum_needed == pytest.approx(0.0033 * math.radians(30.0), rel=1e-14)
    assert r.momentum_needed == pytest.approx(r.torque * 1.0, rel=1e-12)  # eq. 5, t/2 = 1 s
    assert math.degrees(r.gimbal_angle_reached) == pytest.approx(35.0, rel=1e-14)
    x = RATE * 1.0
    assert r.momentum_fraction == pytest.approx(math.sin(x) / x, rel=1e-12)
    assert 100 * r.momentum_fraction == pytest.approx(93.9, abs=0.05)
    # the rate and the flywheels that would hold it: put back into eq. 12
    w = r.gimbal_rate_needed
    assert 4 * h0 * math.sin(BETA) * math.sin(w * 1.0) == pytest.approx(r.momentum_needed)
    assert math.degrees(w) == pytest.approx(37.65, abs=0.005)
    h_need = r.momentum_per_flywheel_needed
    assert 4 * h_need * math.sin(BETA) * math.sin(x) == pytest.approx(r.momentum_needed)
    (warning,) = r.warnings
    assert "93.9 %" in warning and "37.65 deg/s" in warning and "0.9224 mN m s" in warning


def test_no_gimbal_rate_is_enough_past_the_envelope():
    """At 60 deg/s over 1 s, x = 1.047 rad > 1: J w / (4 h0 sin(beta)) = x with h0 from eq. 7,
    beyond the envelope along yaw (sin <= 1), so no rate holds it; bigger flywheels do."""
    r = size_cluster(**TABLE5, gimbal_rate=math.radians(60.0))
    assert r.gimbal_rate_needed is None
    assert r.momentum_needed / (4 * r.momentum * math.sin(BETA)) == pytest.approx(math.pi / 3)
    assert "no gimbal rate is enough" in r.warnings[0]
    assert r.to_json()["gimbal_rate_needed_deg_s"] is None


def test_sized_by_eq_7_the_share_is_always_below_one():
    """Gimbals that reach only a small angle by t/2 lose little, sin(x)/x -> 1, but with h0
    from eq. 7 the share never reaches 1 (sin x < x): the warning is for any shortfall."""
    r = size_cluster(math.radians(30.0), 20.0, 0.0033, gimbal_rate=math.radians(1.0))
    x = math.radians(1.0) * 10.0
    assert r.momentum_fraction == pytest.approx(math.sin(x) / x, rel=1e-12) and r.warnings


def test_cli_echoes_the_inputs_as_given_and_warns(tmp_path, capsys):
    out = tmp_path / "size.json"
    assert run(["cmg", "size", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    d = json.loads(out.read_text())
    # as typed (they were 29.999999999999996 and 3999.9999999999995: radians and back)
    assert d["inputs"]["angle_deg"] == 30.0 and d["inputs"]["flywheel_speed_rpm"] == 4000.0
    assert d["inputs"]["gimbal_rate_deg_s"] == 35.0 and d["inputs"]["skew_deg"] == 54.73
    assert d["gimbal_angle_reached_deg"] == 35.0
    assert d["momentum_fraction"] == pytest.approx(math.sin(RATE) / RATE, rel=1e-12)
    assert d["gimbal_rate_needed_deg_s"] == pytest.approx(37.652, abs=1e-3)
    assert re.search(r"cluster momentum there \(eq\. 12\)\s+1\.622\s+mN m s", text)
    assert re.search(r"share of what is needed\s+93\.9\s+%", text)
    (warning,) = [ln for ln in text.splitlines() if ln.startswith("warning: ")]
    assert warning.removeprefix("warning: ") == d["warnings"][0]
    assert run(["cmg", "size", "--angle-deg", "33.3", "--flywheel-rpm", "3700",
                "--json", str(out), "--force"]) == 0  # fmt: skip
    d = json.loads(out.read_text())
    assert d["inputs"]["angle_deg"] == 33.3 and d["inputs"]["flywheel_speed_rpm"] == 3700.0
