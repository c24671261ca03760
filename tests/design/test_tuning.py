"""Tuning: gains from a specification, the verdict, robustness, bad input."""

import json
import math

import numpy as np
import pytest
from cli_run import run

from airbearing import quaternion as quat
from airbearing.analysis.simulation.scenarios import slew
from airbearing.cli.gains import _echo_checks
from airbearing.design.loops import make_loop
from airbearing.design.margins import analyse_loop
from airbearing.design.tuning import Spec, evaluate, tune
from airbearing.design.tuning.box import _corner_grid
from airbearing.design.tuning.responses import _scenario_run
from airbearing.design.tuning.screening import _Fast
from airbearing.errors import InputError
from airbearing.io.testbed import load_testbed

#: seed 001 Table 6: K_p, K_i, K_w of the yaw CMG loop (eq. 19)
SEED001_TABLE6 = {"K_p": 6.0, "K_i": 0.001, "K_w": 6.0}
#: what `airbearing gains seed004-platform --offset-range-mm -3.9 0.5` returned before the
#: tuner searched a design family: K_p = 0 cannot hold r_z = +0.5 mm (the CM above the
#: bearing, an inverted pendulum), so the loop is unstable at that end of the range
UNSTABLE_BALANCING = {"K_p": 0.0, "K_d": 0.008969, "K_dK_i": 3.197e-05}


@pytest.fixture(scope="module")
def cmg_tb():
    return load_testbed("cmg-yaw")


@pytest.fixture(scope="module")
def tuned_attitude(cmg_tb, tuned_once):
    # tune(cmg_tb, "attitude", Spec(...)), once per test run: the API's notebook test tunes
    # the same loop to the same (default) specification
    return tuned_once(cmg_tb, "attitude", Spec(phase_margin_deg=45.0, gain_margin_db=6.0))


@pytest.fixture(scope="module")
def seed_verdict(cmg_tb):
    """Seed 001's Table 6 gains judged exactly as the tuner judges its own."""
    return evaluate(make_loop(cmg_tb, "attitude", gains=SEED001_TABLE6), Spec())


@pytest.mark.slow
def test_tuned_attitude_gains_meet_the_spec(tuned_attitude, cmg_tb):
    r = tuned_attitude
    assert r.met, r.message
    # re-check independently of the tuner, at every corner (inertia +-15 %)
    loop = make_loop(cmg_tb, "attitude", gains=r.gains)
    checks, worst, per = evaluate(loop, r.spec)
    assert all(c.met for c in checks)
    assert worst["phase_margin_deg"] >= 45 and worst["gain_margin_db"] >= 6
    assert len(per) == 3  # J x 0.85, 1, 1.15
    d = r.to_json()
    assert set(d["gains"]) == {"K_p", "K_i", "K_w"} and d["met"] is True
    # keys added by the step-response check and the search (none renamed)
    assert {"overshoot_pct", "settling_time_s", "crossover_rad_s"} <= set(d["worst_case"])
    assert {"speed_rad_s", "damping", "integral_ratio", "objective"} <= set(d["design"])
    assert all("note" in c for c in d["checks"])
    names = [c["name"] for c in d["checks"]]
    assert "overshoot (%)" in names and "settling time, 2 % (s)" in names
    assert "180 deg slew, settling to 1.5 deg (s)" in names
    assert {"slew_overshoot_pct", "slew_settling_time_s"} <= set(d["worst_case"])


def test_seed001_table6_gains_are_a_design_the_spec_admits(seed_verdict):
    """The reviewer's numbers for seed 001 Table 6 (6, 0.001, 6) through the same checks:
    worst-case phase margin 50.4 deg, gain margin 18.6 dB, |S| peak 1.455, w_B 0.959 rad/s
    (all at J x 0.85 or 1.15), overshoot 0.03 % (independent oracle below)."""
    checks, worst, _ = seed_verdict
    assert all(c.met for c in checks), [str(c) for c in checks if not c.met]
    assert worst["phase_margin_deg"] == pytest.approx(50.41, abs=0.02)
    assert worst["gain_margin_db"] == pytest.approx(18.61, abs=0.02)
    assert worst["sensitivity_peak"] == pytest.approx(1.455, abs=1e-3)
    assert worst["bandwidth_rad_s"] == pytest.approx(0.959, abs=1e-3)
    assert worst["overshoot_pct"] < 0.05


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_tuned_cmg_yaw_is_at_least_as_fast_as_seed_001(tuned_attitude, seed_verdict):
    """The seed's gains meet the specification, so the fastest admissible design cannot be
    slower: by the objective (the worst-case settling of the linear step into 2 %, seed
    5.95 s at J x 0.85, and of the rate-limited 180 deg slew into 1.5 deg, seed 7.5 s)
    and, as it turns out, by the worst-case sensitivity bandwidth (seed 0.959 rad/s) and
    the slowest crossover (seed 1.60 rad/s at J x 1.15) too."""
    _, seed, _ = seed_verdict
    r = tuned_attitude.worst_case

    def objective(w):
        return max(w["settling_time_s"], w["slew_settling_time_s"])

    assert tuned_attitude.met
    assert objective(r) <= objective(seed)
    assert r["settling_time_s"] <= seed["settling_time_s"]
    assert r["bandwidth_rad_s"] >= seed["bandwidth_rad_s"]
    assert r["crossover_rad_s"] >= seed["crossover_rad_s"]
    assert r["overshoot_pct"] <= tuned_attitude.spec.max_overshoot
    by = {c.name: c for c in tuned_attitude.checks}
    assert by["overshoot (%)"].met and by["overshoot (%)"].limit == 5.0
    assert "overshoot (%)" in tuned_attitude.message and "settling time" in tuned_attitude.message


def _seed001_yaw_step(gains, J, h0, dt, fg, n):
    """Independent oracle: seed 001's discrete yaw loop rebuilt in plain NumPy, linearised
    (q_v = yaw error / 2), for a unit yaw step: returns the true yaw at the samples.

    Gyro low-pass eq. 3, attitude propagated with the previous filtered rate (eq. 21), PID
    eq. 19 with the integral of the current error, body torque = h0 x command, one sample
    of computation delay, and the rigid body J yaw'' = torque under a zero-order hold.
    """
    kp, ki, kw = gains["K_p"], gains["K_i"], gains["K_w"]
    yaw = rate = filtered = estimate = integral = pending = 0.0
    out = np.empty(n)
    for k in range(n):
        out[k] = yaw
        estimate += filtered * dt
        filtered = (1 - fg) * filtered + fg * rate
        q = 0.5 * (estimate - 1.0)
        integral += q * dt
        torque, pending = pending, -h0 * (kp * q + ki * integral + kw * filtered)
        yaw += rate * dt + 0.5 * torque / J * dt**2
        rate += torque / J * dt
    return out


def test_step_response_matches_an_independent_oracle(cmg_tb):
    """Overshoot and 2 % settling of the verdict's linear step (the closed loop python-control
    interconnects) against the plain-NumPy loop, nominal inertia, for the seed's gains and
    for gains whose integral overshoots (K_i 100 times the seed's tuned ratio)."""
    dt = cmg_tb.sensors.dt
    for gains in (SEED001_TABLE6, {"K_p": 3.64, "K_i": 0.375, "K_w": 3.45}):
        loop = make_loop(cmg_tb, "attitude", gains=gains)
        _, worst, _ = evaluate(loop, Spec(), actuators=False, corner_set=[("nominal", loop.p)])
        y = _seed001_yaw_step(
            gains, cmg_tb.body.yaw_inertia, cmg_tb.cmg.h0, dt, cmg_tb.sensors.lowpass, 4000
        )
        overshoot = 100 * (y.max() - 1.0)
        out = np.nonzero(np.abs(y - 1.0) > 0.02)[0]
        settling = (out[-1] + 1) * dt
        assert worst["overshoot_pct"] == pytest.approx(overshoot, abs=1e-6)
        assert worst["settling_time_s"] == pytest.approx(settling, abs=1e-9)
    # the seed's: 0.03 % and 5.50 s, as the reviewer's own oracle found
    assert _seed001_yaw_step(SEED001_TABLE6, 0.00283, cmg_tb.cmg.h0, dt, 0.25, 4000).max() < 1.001


@pytest.mark.parametrize(
    ("name", "loop", "split"),
    [("cmg-yaw", "attitude", None), ("seed000-tabletop", "balancing", "mixed")],
    ids=["cmg-yaw", "seed000-mixed"],
)
@pytest.mark.slow
def test_the_searchs_margins_agree_with_analyse_loop(name, loop, split):
    """Agreement between methods: the search's NumPy loop against python-control's
    analyse_loop, every corner, seed gains (seed000's mixed loop has the lightly damped
    pendulum mode whose fast phase turn the search refines)."""
    opts = {} if split is None else {"split": split}
    base = make_loop(load_testbed(name), loop, **opts)
    grid = _corner_grid(base, Spec())
    fast = _Fast(base, Spec(), grid, set())
    K, K_fr = fast._controller(base.gains)
    for c, (_, p, _) in zip(fast.corners, grid, strict=True):
        f = fast.margins(c, K, K_fr)
        a = analyse_loop(base.with_params(p), multiloop=False, n_freq=1000).worst()
        assert f["stable"] == a["stable"]
        # grids of 500 and 1000 points, crossings interpolated or refined: 0.05 deg, 0.05 dB
        assert f["pm"] == pytest.approx(a["phase_margin_deg"], abs=0.05)
        assert f["gm"] == pytest.approx(a["gain_margin_db"], abs=0.05)
        # the |S| peak: both refine it between their grid points (a lightly damped peak,
        # seed000, lies up to 2.5 % above a 1000-point grid's largest value: 1.220 where
        # a dense grid of 2e5 points and the refined peak find 1.248)
        assert f["ms"] == pytest.approx(a["sensitivity_peak"], rel=2e-4)
        assert f["wb"] == pytest.approx(a["bandwidth_rad_s"], rel=1e-3)
        s = fast.step(c, K, f["wb"], True)
        _, _, overshoot, settling = _scenario_run(base.with_params(p), a["bandwidth_rad_s"])
        assert s["overshoot"] == pytest.approx(overshoot, abs=1e-6)
        assert s["settling"] == pytest.approx(settling, abs=1e-9)


@pytest.mark.slow
def test_bandwidth_0_15_hz_is_met_on_cmg_yaw(tmp_path, capsys):
    """Seed 001's Table 6 gains have a worst-case bandwidth of 0.153 Hz and meet every check,
    so a design at 0.15 Hz exists: the tuner must find one."""
    out = tmp_path / "g.json"
    assert run(["-q", "gains", "cmg-yaw", "--bandwidth-hz", "0.15", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["met"] is True
    bw = next(c for c in doc["checks"] if c["name"] == "bandwidth (Hz)")
    assert bw["met"] and 0.15 <= bw["value"] < 0.16  # at the requested bandwidth, not faster
    assert doc["spec"]["bandwidth_hz"] == 0.15 and doc["spec"]["max_overshoot"] == 5.0
    assert "specification met: yes" in capsys.readouterr().out


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_an_unstable_loop_shows_no_met_margin(capsys):
    """Margins of an unstable closed loop mean nothing: not met, no value, the reason."""
    tb = load_testbed("seed004-platform")
    lp = make_loop(tb, "balancing", split="mechanical", gains=UNSTABLE_BALANCING)
    checks, worst, _ = evaluate(lp, Spec(offset_range=(-3.9e-3, 0.5e-3)))
    assert not worst["stable"]
    stable, rest = checks[0], checks[1:]
    assert stable.name == "stable at every corner" and not stable.met
    assert "r_z = 0.5 mm" in stable.note and "r_z = -3.9 mm" not in stable.note
    names = {c.name for c in rest}
    assert {"phase margin (deg)", "gain margin (dB)", "sensitivity peak"} <= names
    for c in rest:
        assert not c.met and c.value is None and c.note.startswith("not applicable"), c
    _echo_checks([c.to_json() for c in checks], False)
    lines = capsys.readouterr().out.splitlines()
    rows = [line for line in lines if line.startswith(("phase", "gain", "sensitivity"))]
    # one channel at a time (3) and both channels at once (2: sliders 1 and 2)
    assert len(rows) == 5 and all(line.split()[-1] == "n/a" for line in rows), rows
    assert not any(line.rstrip().endswith(" met") and "NOT" not in line for line in lines)
    assert "not applicable to an unstable loop" in lines[-1]


def test_an_offset_range_no_design_meets_is_reported_not_relaxed():
    """r_z up to +0.5 mm: the tuner returns the design that misses least, and says what
    misses; no margin of an unstable loop reads as met. The nominal inertia only (the three
    offsets, not nine corners: a third of the work): the same checks miss as over the
    inertia box (phase margin, |S| peak, overshoot, both margins of all channels at once)."""
    spec = Spec(offset_range=(-3.9e-3, 0.5e-3), inertia_uncertainty=0.0)
    r = tune(load_testbed("seed004-platform"), "balancing", spec, split="mechanical")
    assert not r.met and r.spec == spec and "NOT met" in r.message
    if not r.worst_case["stable"]:
        assert all(c.value is None and not c.met for c in r.checks[1:])


@pytest.mark.slow
def test_impossible_spec_is_reported_not_relaxed(cmg_tb):
    # the nominal inertia only (one corner, not three): no design meets it there either
    spec = Spec(phase_margin_deg=85, gain_margin_db=20, bandwidth_hz=2.0, inertia_uncertainty=0)
    r = tune(cmg_tb, "attitude", spec)
    assert not r.met
    assert r.spec == spec  # the specification is never relaxed
    failed = [c for c in r.checks if not c.met]
    assert failed and "NOT met" in r.message


@pytest.mark.slow
def test_balancing_loop_of_seed004_meets_its_spec():
    """seed 004's platform (mechanical split: no cage field) tunes to the default spec over
    the default box, the offset before and after step two, and gives AT_THE_EDGE's gains."""
    r = tune(load_testbed("seed004-platform"), "balancing", Spec(), split="mechanical")
    assert r.met, r.message
    assert r.worst_case["overshoot_pct"] <= 5.0 and math.isfinite(r.worst_case["settling_time_s"])
    assert len(r.corners) == 9  # 3 inertias x 3 vertical offsets
    assert {label.split(", ")[1] for label, _ in r.corners} == {
        "r_z = -3.9 mm", "r_z = -2.6 mm", "r_z = -0.052 mm"}  # fmt: skip
    assert r.gains == pytest.approx(AT_THE_EDGE["seed004-platform"][2], rel=2e-3)


def test_the_default_offset_box_runs_from_before_to_after_step_two():
    """The default vertical-offset range of a platform: the testbed's offset +50 % (not yet
    identified) to the 2 % seed 004's step two leaves, which is the offset ``balance``
    simulates by default (runs.balanced_vertical_offset): the same number in both."""
    from airbearing.analysis.balancing import runs
    from airbearing.design.tuning import box

    assert box._STEP2_ERROR == runs.STEP2_ERROR
    for name in ("seed004-platform", "seed000-tabletop"):
        tb = load_testbed(name)
        lo, hi = box.offset_range(make_loop(tb, "balancing", split="mechanical"), Spec())
        assert lo == pytest.approx(1.5 * tb.body.cm_offset_vec[2])  # -3.9 mm
        assert hi == pytest.approx(runs.balanced_vertical_offset(tb))  # -0.052 mm
    # given: as given; the testbed's own offset is a corner only when inside the range
    lp = make_loop(load_testbed("seed004-platform"), "balancing", split="mechanical")
    assert box.offset_range(lp, Spec(offset_range=(-1e-4, 0.0))) == (-1e-4, 0.0)
    labels = [label for label, _ in box.corners(lp, Spec(offset_range=(-1e-4, 0.0)))]
    assert {x.split(", ")[1] for x in labels} == {"r_z = -0.1 mm", "r_z = -0.05 mm", "r_z = 0 mm"}
    assert box.offset_range(make_loop(load_testbed("cmg-yaw"), "attitude"), Spec()) is None


@pytest.mark.slow
def test_balancing_tuning_reports_the_unreachable_trim():
    """platform-3dof needs sliders at -61/-108 mm to balance: past the 37 mm travel. The
    search still finds the fastest design that meets the rest (the travel does not drive
    it): every other check is met, the margin of its four channels at once included (the
    previous tuner's gains missed it by 15.6 deg), and the report on the tuned gains
    agrees. The nominal inertia only (the three vertical offsets of the default box, not
    nine corners: a third of the work); the default box's gains are AT_THE_EDGE's."""
    from airbearing.reporting.stability import stability_report

    tb = load_testbed("platform-3dof")
    r = tune(tb, "balancing", Spec(inertia_uncertainty=0.0), split="mixed")
    by = {c.name: c for c in r.checks}
    assert by["phase margin (deg)"].met and by["gain margin (dB)"].met
    assert by["phase margin, all channels at once (deg)"].met
    assert not by["slider travel (m)"].met and not r.met
    # every other check is met: no gains move the trim
    assert [c.name for c in r.checks if not c.met] == ["slider travel (m)"]
    # a design of the search, not the candidate that misses least (what it returns when
    # nothing is admissible)
    assert r.design["speed_rad_s"] is not None
    _, report = stability_report(tb, "balancing", gains=r.gains, split="mixed", spec=r.spec)
    assert report["met"] is r.met
    assert [(c["name"], c["met"]) for c in report["checks"]] == [(c.name, c.met) for c in r.checks]
    # seed 004 eqs. 4-5: travel needed = mass |r_y| / m_2
    want = tb.body.mass * abs(tb.body.cm_offset_vec[1]) / tb.masses.mass_vec[1]
    assert by["slider travel (m)"].value == pytest.approx(want, rel=0.02)  # + transient
    assert [label for label, _ in r.corners] == [
        "J x 1, r_z = -3.9 mm", "J x 1, r_z = -2.6 mm", "J x 1, r_z = -0.052 mm"]  # fmt: skip


@pytest.mark.slow
def test_tuned_attitude_gains_converge_in_the_nonlinear_loop(tuned_attitude, cmg_tb):
    """A 90 deg slew (seed 001 Table 8) with the tuned gains, noise and low-pass on."""
    r = slew(
        cmg_tb, angle_deg=90, duration=40, gains=tuple(r_ for r_ in tuned_attitude.gains.values())
    )
    q_end = quat.from_yaw(r.x[-1, 0])
    err = quat.qmul(quat.qconj(quat.from_yaw(math.radians(90))), q_end)
    # seed 001 Sec. 5 declares steady state within a_err = 1.5 deg (Table 6)
    assert math.degrees(2 * math.acos(min(1.0, abs(err[0])))) < 1.5
    assert abs(r.x[-1, 1]) < math.radians(0.5)  # at rest: below 0.5 deg/s


def _slew_metrics(run, angle_deg):
    """Overshoot (% of the slew) and 2 % settling time (s) of a nonlinear slew."""
    df = run.to_pandas()
    e = np.degrees(np.unwrap(df.true_yaw.to_numpy()) - df.yaw_ref.to_numpy())
    out = np.nonzero(np.abs(e) > 0.02 * angle_deg)[0]
    return 100 * e.max() / angle_deg, float(df.t.to_numpy()[out[-1] + 1])


@pytest.mark.slow
def test_the_rate_limited_slew_agrees_with_the_nonlinear_simulation(cmg_tb, tuned_attitude):
    """Agreement between methods: the verdict's 180 deg slew (the linear discrete loop with
    the gimbal rates limited, seed 001 eq. 4) against the nonlinear simulation, for seed
    001's gains, the tuned gains and gains whose integral winds up (K_i / K_p = 0.1):
    settling into 1.5 deg to 0.5 s (the quaternion error's sine and the gimbals' drift
    are what the linear loop leaves out), overshoot to 5 points of percent."""
    from airbearing.design.tuning.slew import _loop_slew

    winding = {"K_p": 3.64, "K_i": 0.375, "K_w": 3.45}
    for gains in (SEED001_TABLE6, tuned_attitude.gains, winding):
        overshoot, settling = _loop_slew(make_loop(cmg_tb, "attitude", gains=gains))
        run = slew(cmg_tb, angle_deg=180.0, duration=60.0, ideal=True, gains=gains)
        df = run.to_pandas()
        e = np.degrees(np.unwrap(df.true_yaw.to_numpy()) - df.yaw_ref.to_numpy())
        out = np.nonzero(np.abs(e) > 1.5)[0]
        assert settling == pytest.approx(df.t.to_numpy()[out[-1] + 1], abs=0.5), gains
        assert overshoot == pytest.approx(100 * e.max() / 180.0, abs=5.0), gains


@pytest.mark.slow
@pytest.mark.parametrize("angle_deg", [30.0, 180.0])
def test_tuned_gains_slew_faster_than_the_seeds_without_overshoot(
    tuned_attitude, cmg_tb, angle_deg
):
    """The nonlinear slews the reviewer ran: the tuned gains overshoot within the spec and
    settle no later than seed 001's Table 6 gains (30 deg: the linear regime; 180 deg: the
    gimbal rates saturate and the quaternion error saturates at sin(90 deg))."""
    ours = _slew_metrics(slew(cmg_tb, angle_deg=angle_deg, duration=40.0, ideal=True,
                              gains=tuned_attitude.gains), angle_deg)  # fmt: skip
    seed = _slew_metrics(slew(cmg_tb, angle_deg=angle_deg, duration=40.0, ideal=True,
                              gains=SEED001_TABLE6), angle_deg)  # fmt: skip
    assert ours[0] <= tuned_attitude.spec.max_overshoot
    assert ours[1] <= seed[1], (ours, seed)


@pytest.mark.slow
def test_the_tuned_gains_end_a_180_deg_slew_within_the_campaigns_spec(cmg_tb, tuned_attitude):
    """The robust-verification campaign's spec (docs: final_yaw_error_deg <= 0.5 after a
    40 s, 180 deg slew): an integral that winds up while the gimbal rates saturate leaves
    an error that outlasts the slew (1.7 deg with gains placed for the linear step alone)."""
    from airbearing.analysis.simulation.scenarios import slew_summary

    run = slew(cmg_tb, angle_deg=180.0, duration=40.0, gains=tuned_attitude.gains)
    assert slew_summary(run)["final_yaw_error_deg"] <= 0.5


@pytest.mark.parametrize(
    "kwargs",
    [
        {"phase_margin_deg": -10},
        {"gain_margin_db": -3},
        {"max_sensitivity": 0.5},
        {"bandwidth_hz": -1},
        {"offset_range": (1e-3, -1e-3)},
        {"max_overshoot": -1.0},
        {"max_overshoot": math.nan},
        {"max_settling_time": 0.0},
    ],
    ids=[
        "negative-pm",
        "negative-gm",
        "ms-below-1",
        "negative-bw",
        "reversed-range",
        "negative-overshoot",
        "nan-overshoot",
        "zero-settling",
    ],
)
def test_bad_specs_are_input_errors(kwargs):
    with pytest.raises(InputError):
        Spec(**kwargs)


@pytest.mark.parametrize(
    ("flag", "value"),
    [("--max-overshoot-pct", "-1"), ("--max-overshoot-pct", "nan"), ("--max-settling-time-s", "0")],
)
def test_bad_step_flags_exit_2(flag, value, tmp_path):
    out = tmp_path / "g.json"
    assert run(["-q", "gains", "cmg-yaw", flag, value, "--json", str(out)]) == 2
    assert not out.exists()


def test_bad_loop_and_gains_are_input_errors(cmg_tb):
    with pytest.raises(InputError, match="loop='pitch'"):
        make_loop(cmg_tb, "pitch")
    with pytest.raises(InputError, match="kind = 'platform'"):
        make_loop(cmg_tb, "balancing")
    with pytest.raises(InputError, match="not gains of this loop"):
        make_loop(cmg_tb, "attitude", gains={"K_p": 1, "K_d": 1, "K_dK_i": 1})
    with pytest.raises(InputError, match="Nyquist"):
        tune(cmg_tb, "attitude", Spec(bandwidth_hz=15.0))
    assert np.isfinite(make_loop(cmg_tb, "attitude").gain_vector).all()


def test_a_settling_time_that_never_comes_says_so(capsys):
    """inf is null in JSON (none): the note and the table say what it means."""
    from airbearing.design.tuning import Check
    from airbearing.design.tuning.spec import _check

    c = _check("settling time, 2 % (s)", math.inf, None, "<=")
    assert c.met and c.to_json()["value"] is None  # reported, no limit: nothing to fail
    c = Check(c.name, c.value, None, "<=", True, None, "does not settle within 2400 s")
    _echo_checks([c.to_json()], True)
    row = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("settling"))
    assert "does not settle" in row and row.split()[-1] == "reported"


#: Gains the tuner gives with the margin of all channels at once in its checks and, for
#: the balancing loops, the box of the offset before and after seed 004's step two
#: (`airbearing gains TESTBED --json`, this version): each sits at the edge of that margin.
AT_THE_EDGE = {
    "cmg-yaw": ("attitude", None, {"K_p": 8.113, "K_i": 0.00856, "K_w": 6.555}),
    "seed004-platform": ("balancing", "mechanical",
                         {"K_p": 0.0162, "K_d": 0.0966, "K_dK_i": 0.00371}),
    "seed000-tabletop": ("balancing", "mixed",
                         {"K_p": 0.002935, "K_d": 0.03301, "K_dK_i": 0.0002075}),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(AT_THE_EDGE))
def test_the_searchs_simultaneous_margin_agrees_with_the_verdicts(name):
    """Agreement between methods: the search's screening of the margin with every channel
    at once (a Perron-scaled bound of mu on its grid, D-scaled where it would fail,
    refined only near the limit) against the verdict's multiloop_disk_margin (mu's
    D-scaled bound, every peak refined), at every corner of the default box, for gains at
    the edge of the 45 deg limit. Near the limit they agree to 0.05 deg, the search's
    tolerance (_INSIDE), and what the screening passes the verdict passes."""
    from airbearing.design.margins import multiloop_disk_margin
    from airbearing.design.tuning.screening import _INSIDE

    loop, split, gains = AT_THE_EDGE[name]
    base = make_loop(load_testbed(name), loop, **({} if split is None else {"split": split}))
    spec = Spec(offset_range=(-3.9e-3, -0.052e-3)) if loop == "balancing" else Spec()
    grid = _corner_grid(base, spec)
    fast = _Fast(base, spec, grid, set())
    K, K_fr = fast._controller(gains)
    near = 0
    for c, (label, p, _) in zip(fast.corners, grid, strict=True):
        m = fast.margins(c, K, K_fr)
        exact = multiloop_disk_margin(base.with_params(p).with_gains(gains).loop_transfer(None))
        pm, gm = exact["disk_phase_margin_deg"], exact["disk_gain_margin_db"]
        if abs(pm - spec.phase_margin_deg) < 5:
            near += 1
            assert m["ml_pm"] == pytest.approx(pm, abs=_INSIDE["pm"]), label
            assert m["ml_gm"] == pytest.approx(gm, abs=_INSIDE["gm"]), label
        if m["ml_pm"] >= spec.phase_margin_deg + _INSIDE["pm"]:
            assert pm >= spec.phase_margin_deg, label
        if m["ml_gm"] >= spec.gain_margin_db + _INSIDE["gm"]:
            assert gm >= spec.gain_margin_db, label
    assert near >= 1  # the gains are at the edge somewhere in the box


#: What `airbearing gains TESTBED --loop balancing` gave before its box reached the
#: balanced platform (the testbed's offset +-50 % only) and before it checked the margin of
#: all channels at once.
PREVIOUS_BALANCING = {
    "seed004-platform": {"K_p": 0.07894, "K_d": 0.07015, "K_dK_i": 0.07521},
    "seed000-tabletop": {"K_p": 0.1934, "K_d": 0.1458, "K_dK_i": 0.1192},
}


def _balance(name, gains, offset_stays):
    """``airbearing balance NAME`` with the gains, its default scenario (seed 000: sliders
    at -0.5 mm, the platform at the offset step two leaves, 2 % of the testbed's), ideal
    sensors; 200 s. Returns the slider 1-2 settling time into max(2 % of the move, twice
    the backlash) (s), their overshoot (% of the move) and the largest tilt (deg) over the
    whole run and over its last 50 s."""
    from airbearing.analysis.balancing.runs import run_balancing

    tb = load_testbed(name)
    method = AT_THE_EDGE[name][1]
    run = run_balancing(tb, method, gains=[gains[k] for k in ("K_p", "K_d", "K_dK_i")],
                        duration=200.0, noise=False, free_duration=None,
                        offset_stays=offset_stays)  # fmt: skip
    df = run.result.to_pandas()
    t = df.t.to_numpy()
    settle, over = 0.0, 0.0
    for c in ("s1", "s2"):
        s = df[c].to_numpy()  # the balance is at the rail zero (runs.py)
        out = np.nonzero(np.abs(s) > max(0.02 * abs(s[0]), 2 * tb.masses.backlash))[0]
        settle = max(settle, math.inf if out.size and out[-1] == len(s) - 1 else
                     (t[out[-1] + 1] if out.size else 0.0))  # fmt: skip
        over = max(over, 100 * float(np.max(-s / s[0])))
    tilt = np.degrees(2 * np.arcsin(np.clip(np.hypot(df.true_qx, df.true_qy), 0, 1))).to_numpy()
    return settle, over, float(tilt.max()), float(tilt[t > t[-1] - 50].max())


@pytest.mark.parametrize("name", ["seed004-platform", "seed000-tabletop"])
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_tuned_balancing_gains_settle_in_the_default_balance_scenario(name):
    """The nonlinear closed loop (sliders with their steps, speed and backlash) of
    ``balance`` with its defaults, the gains the tuner now gives (AT_THE_EDGE), both as the
    seed ran it (the law commands positions from the balanced rail zero) and with the
    offset an imbalance the integral must find (offset_stays): the sliders settle within
    40 s and the platform ends level to 0.2 deg (seed004-platform: 0.14 deg, the limit
    cycle of 10 um motor steps on a platform 52 um pendulous). The previous gains made
    seed000-tabletop fall over (tilt past 90 deg) and overshot seed004-platform's sliders
    by 42 % with the offset staying."""
    gains = AT_THE_EDGE[name][2]
    for stays in (False, True):
        settle, over, _, tilt_end = _balance(name, gains, stays)
        assert settle <= 40.0 and tilt_end < 0.2, (stays, settle, tilt_end)
        if stays:
            assert over < 5.0  # seed004-platform 2.0 %, seed000-tabletop 0
    settle, over, tilt, _ = _balance(name, PREVIOUS_BALANCING[name], True)
    if name == "seed000-tabletop":
        assert tilt > 90.0  # it fell over
    else:
        assert over > 30.0  # 42 %
