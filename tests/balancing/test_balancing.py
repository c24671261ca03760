"""Automatic balancing (seeds 000 and 004): maps, splits, actuators, closed loops, CLI."""

from __future__ import annotations

import dataclasses
import json

import casadi as ca
import numpy as np
import pytest

from airbearing import quaternion as quat
from airbearing.analysis.balancing.comparison import compare_methods
from airbearing.analysis.balancing.runs import run_balancing
from airbearing.analysis.simulation.simulate import simulate
from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.balancing import (
    MECHANICAL,
    MIXED,
    PIDSplit,
    balancing_controller,
    in_plane_pid,
    lyapunov_balancing_controller,
    torque_to_sliders,
)
from airbearing.errors import InputError
from airbearing.io.testbed import Field, load_testbed
from airbearing.models.model import build_model

RNG = np.random.default_rng(20240501)
S45 = np.sqrt(0.5)
RAILS = {
    "orthogonal": np.eye(3),
    # seed 004: rails rotated 45 deg about z
    "rotated-45-z": np.array([[S45, S45, 0.0], [-S45, S45, 0.0], [0.0, 0.0, 1.0]]),
    "skewed": np.array([[1.0, 0.2, 0.1], [0.0, 1.0, 0.3], [0.2, 0.0, 1.0]]),
}
MASSES = np.array([0.041, 0.041, 0.041])  # kg, seed 000 Sec. 2


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _slider_torque_numpy(s, g_body, axes, masses):
    """Independent re-derivation: sum_i m_i s_i u_i x g (seed 000 eq. 2)."""
    return sum(m * si * np.cross(u, g_body) for m, si, u in zip(masses, s, axes, strict=True))


@pytest.mark.parametrize("rails", list(RAILS), ids=list(RAILS))
@pytest.mark.parametrize("trial", range(5))
def test_torque_to_sliders_reproduces_torque_orthogonal_to_g(rails, trial):
    axes = _unit(RAILS[rails])
    g_hat = _unit(RNG.normal(size=3) * [0.2, 0.2, 1.0] - [0, 0, 3])
    tau = RNG.normal(size=3) * 1e-3
    tau -= tau @ g_hat * g_hat  # the part gravity can make
    s = torque_to_sliders(tau, g_hat, 9.81, axes, MASSES)
    got = _slider_torque_numpy(s, 9.81 * g_hat, axes, MASSES)
    # exact algebra (seed 000 eq. 5 / seed 004 eq. 13): round-off only
    np.testing.assert_allclose(got, tau, rtol=0, atol=1e-12 * np.linalg.norm(tau))


def test_torque_to_sliders_drops_component_along_g():
    g_hat = np.array([0.0, 0.0, -1.0])
    s = torque_to_sliders([1e-3, 2e-3, 5e-3], g_hat, 9.81, np.eye(3), MASSES)
    got = _slider_torque_numpy(s, 9.81 * g_hat, np.eye(3), MASSES)
    # gravity torques are orthogonal to g: the z part cannot be made (round-off tolerance)
    np.testing.assert_allclose(got, [1e-3, 2e-3, 0.0], atol=1e-15)


@pytest.mark.parametrize("split", [MIXED, MECHANICAL, PIDSplit("magnetorquers", "sliders",
                                                               "magnetorquers")],
                         ids=["mixed", "mechanical", "P-and-D-magnetic"])  # fmt: skip
def test_split_sums_to_pid_torque(split):
    g_hat = _unit([0.03, -0.02, -1.0])
    b_body = -6e-4 * g_hat  # seed 000: field anti-parallel to gravity, 6e-4 T
    w = np.array([2e-3, -1e-3, 0.5])
    integral = np.array([0.4, -0.3, 0.2])
    tau_p, tau_i, tau_d = in_plane_pid(g_hat, w, integral, (1e-3, 1.8e-3, 2e-5))
    ds, d = split.commands(tau_p, tau_i, tau_d, g_hat=g_hat, gravity=9.81, b_body=b_body,
                           axes=np.eye(3), masses=MASSES)  # fmt: skip
    total = _slider_torque_numpy(ds, 9.81 * g_hat, np.eye(3), MASSES) + np.cross(d, b_body)
    # every PID term is orthogonal to g (and to the vertical b): exact up to round-off
    np.testing.assert_allclose(total, tau_p + tau_i + tau_d, atol=1e-15)
    if split == MIXED:  # seed 000 eq. 7: d = (K_d / |b|) g_hat x w_perp
        w_perp = w - w @ g_hat * g_hat
        np.testing.assert_allclose(d, 1.8e-3 / 6e-4 * np.cross(g_hat, w_perp), rtol=1e-12)
        assert split.carried_by("magnetorquers") == ("derivative",)


def test_split_rejects_unknown_actuator():
    with pytest.raises(InputError, match="reaction_wheels"):
        PIDSplit("sliders", "reaction_wheels", "sliders")


# ------------------------------------------------------------------------------ actuators


def _run_slider(act, commands, dt=0.05, start=0.0):
    f = act.function(dt)
    st = ca.DM(act.state0([start, 0.0, 0.0]))
    out = []
    for c in commands:
        held, st, motor = f(ca.DM([c, 0.0, 0.0]), st)
        out.append((float(held[0]), float(st[3]), float(motor[0])))
    return np.array(out)


def test_slider_speed_limit_and_steps():
    act = SliderActuator(travel=0.037, step=2e-6, speed=0.005)
    out = _run_slider(act, [1e-3] * 6)
    # seed 000 steps of 2 um; 0.005 m/s * 0.05 s = 0.25 mm per sample (exactly 125 steps)
    np.testing.assert_allclose(out[:4, 2], [2.5e-4, 5e-4, 7.5e-4, 1e-3], atol=1e-15)
    out = _run_slider(act, [1.2345e-5])
    assert abs(out[0, 2] - 1.2e-5) < 1e-15  # rounded to the 2 um grid


def test_slider_backlash_loses_motion_on_reversal():
    b = 2e-5  # seed 004: 0.02 mm
    act = SliderActuator(travel=0.037, backlash=b)
    out = _run_slider(act, [1e-4, 1e-4, 0.9e-4, 1.1e-4])
    # play operator: first move drags the mass b/2 behind the motor; reversing by less than
    # b leaves the mass where it was; exact arithmetic of the operator
    np.testing.assert_allclose(out[1, 1], 1e-4 - b / 2, atol=1e-15)
    np.testing.assert_allclose(out[2, 1], 1e-4 - b / 2, atol=1e-15)
    np.testing.assert_allclose(out[3, 1], 1.1e-4 - b / 2, atol=1e-15)


def test_slider_travel_limit():
    out = _run_slider(SliderActuator(travel=0.037), [0.1])
    assert out[0, 2] == pytest.approx(0.037, abs=1e-15)  # seed 004: +-37 mm


def test_magnetorquer_saturation_per_coil():
    f = MagnetorquerActuator(max_dipole=1.0).function()  # seed 000: 1 A m^2 per coil
    np.testing.assert_allclose(np.asarray(f([2.0, -0.5, -3.0])).ravel(), [1.0, -0.5, -1.0])


# --------------------------------------------------------------------------- closed loops


@pytest.mark.slow
def test_lyapunov_law_drives_q_ep_to_zero_without_noise():
    tb = load_testbed("platform-3dof")
    body = dataclasses.replace(tb.body, cm_offset=(2e-6, -1e-6, -1.3e-7))
    tb = tb.replace(body=body)
    model = build_model(tb)
    ctl = lyapunov_balancing_controller(model, sliders=SliderActuator(travel=tb.masses.travel))
    q0 = quat.from_axis_angle([1.0, 1.0, 0.0], np.deg2rad(3.0))
    r = simulate(model, ctl, duration=600.0, x0=model.x0(q=q0), noise=False)
    qep = r.extra[:, r.controller.extra_names.index("q_ep_norm")]
    # seed 004 eq. 35: V' <= 0, q_ep -> 0. Over 600 s (about 12 integral time constants of
    # the matched gains, 1 / 0.02 s each) the error falls by more than 1e3 from 3 deg
    assert qep[-200:].max() < 1e-3 * qep[0]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["mechanical", "mixed", "adaptive", "lyapunov"])
def test_methods_balance_in_plane_without_noise(method):
    tb = load_testbed("platform-3dof")
    # a nearly neutral platform (one 0.02 mm motor accuracy of a 0.041 kg slider, 0.13 um)
    # started level: the PID's integral pole is then at about 60 s, and the adaptive law,
    # which learns r from the motion (Phi^T w), sees the platform swing
    run = run_balancing(tb, method, duration=300.0, noise=False, ideal_actuators=True,
                        free_duration=None, vertical_offset=-0.041 * 2e-5 / 6.3,
                        start="level", offset_stays=True)  # fmt: skip
    # the offset stays, an imbalance the law must find: balanced is the rail origin (see
    # analysis.balancing), so the in-plane sliders come back from -0.5 mm; 10 % of the
    # offset is a loose bound for a 300 s run
    s = np.asarray(run.metrics["slider_final_m"])
    assert np.all(np.abs(s[:2]) < 0.05e-3), s
    # the run's contract: its JSON is the metrics' (run context included), a short repr
    assert run.to_json()["method"] == method and run.to_json()["start"] == "level"
    assert len(repr(run)) < 300 and f"balancing run, {method}, 300 s" in str(run)


def test_law_positions_are_measured_from_the_balanced_zero():
    """Seed 000 eq. 5 gives slider positions: the sliders leave the offset at once (5 mm/s
    covers 0.5 mm in 0.1 s). With the offset kept they start from it and only the integral
    term, slowly, brings them back."""
    tb = load_testbed("platform-3dof")
    kw = dict(duration=2.0, noise=False, free_duration=None, start="level")

    def motors(run):  # stepper positions (the masses also carry the backlash)
        names = run.result.controller.extra_names
        return run.result.extra[-1, [names.index("motor1"), names.index("motor2")]]

    s_removed = motors(run_balancing(tb, "mixed", **kw))
    s_kept = motors(run_balancing(tb, "mixed", offset_stays=True, **kw))
    assert np.all(np.abs(s_removed) <= tb.masses.step), s_removed
    assert np.all(np.abs(s_kept + 0.5e-3) < 0.05e-3), s_kept


def test_gyro_noise_reaches_sliders_only_in_the_mechanical_split():
    tb = load_testbed("platform-3dof")
    tb = tb.replace(sensors=dataclasses.replace(tb.sensors, gyro_noise=3e-2))
    cmp = compare_methods(tb, ("mechanical", "mixed"), offsets=(-0.5e-3,), seeds=(0,),
                          free_duration=None)  # fmt: skip
    t = cmp.tables[-0.5e-3]
    # the result contract: a short repr, the verdict in a few lines, a table for pandas
    assert len(repr(cmp)) < 300 and repr(cmp).startswith("Comparison(methods=")
    assert "mechanical vs mixed" in str(cmp) and len(str(cmp).splitlines()) <= 6
    df = cmp.to_pandas()
    assert list(df["method"]) == ["mechanical", "mixed"]
    assert df["slider_std_m_1"].iloc[0] == t["mechanical"]["slider_std_m"][0]
    # mechanical: the D term moves the sliders by K_d sigma_w / (m g) = 1.8e-3 * 3e-2 / 0.40
    # = 0.13 mm per sample (1 sigma), far above backlash; mixed sends it to the coils
    assert np.mean(t["mechanical"]["slider_std_m"][:2]) > 5e-5
    assert cmp.ratios["slider_p2p"] < 0.5


def test_adaptive_estimate_follows_the_gravity_direction():
    from airbearing.design.balancing import ADAPTIVE_DEFAULT_GAINS

    tb = load_testbed("platform-3dof")
    run = run_balancing(tb, "adaptive", duration=100.0, noise=False, ideal_actuators=True,
                        free_duration=None, vertical_offset=-1.3e-7, start="level",
                        offset_stays=True)  # fmt: skip
    r = run.result
    names = r.controller.extra_names
    r_hat = r.extra[:, [names.index(f"r_hat_{c}") for c in "xyz"]]
    g_hat = r.y[:, r.model.index(["gx", "gy", "gz"], "y")]
    # g' = g x w in body axes, so r_hat' = gamma m g x w integrates to
    # r_hat - r_hat(0) = k_theta / (m |g|) (g_hat - g_hat(0)); the sampled law (explicit
    # Euler at 20 Hz on ~0.02 rad/s swings) follows it to within a few per cent
    expected = ADAPTIVE_DEFAULT_GAINS[1] / (tb.body.mass * tb.gravity) * (g_hat[-1] - g_hat[0])
    assert np.linalg.norm(expected) > 1e-6
    assert np.linalg.norm(r_hat[-1] - expected) < 0.05 * np.linalg.norm(expected)
    # from the seed-000 rest position, with the offset kept, the platform is already an
    # equilibrium of the law
    rest = run_balancing(tb, "adaptive", duration=60.0, noise=False, free_duration=None,
                         offset_stays=True)  # fmt: skip
    assert "nothing is learnt" in rest.metrics["note"]
    assert np.allclose(rest.metrics["slider_final_m"][:2], -0.5e-3, atol=2e-6)
    # with the offset removed (the sliders go back to the rail zero) the balanced but
    # tilted platform swings and the law learns from that
    moved = run_balancing(tb, "adaptive", duration=60.0, noise=False, free_duration=None)
    assert "not the tilt" in moved.metrics["note"]
    assert np.abs(moved.result.x[:, 4:7]).max() > 1e-3


def test_integral_time_constant_matches_the_linearised_loop():
    from airbearing.analysis.balancing.transient import integral_time_constant
    from airbearing.design.balancing import SEED000_GAINS
    from airbearing.design.loops import balancing_loop

    tb = load_testbed("platform-3dof")
    for r_z in (-52e-6, 0.0, -1e-3):
        t = tb.replace(body=dataclasses.replace(tb.body, cm_offset=(0.0, 0.0, r_z)))
        poles = (
            balancing_loop(t, split="mechanical", delay_samples=0)
            .closed_loop(discrete=False)
            .poles()
        )
        poles = poles[np.abs(poles) > 1e-9]  # the yaw axis is not in the loop
        # the per-axis cubic drops the products of inertia (J_xy = -0.001, J_yz = -0.004
        # kg m^2), which move the slowest pole of the neutral platform by 1.8 %
        assert integral_time_constant(t, SEED000_GAINS, r_z) == pytest.approx(
            1.0 / np.min(-poles.real), rel=0.03
        )


def test_rest_attitude_is_an_equilibrium():
    from airbearing.analysis.balancing.runs import rest_attitude
    from airbearing.design.controller import constant_input

    tb = load_testbed("platform-3dof")
    model = build_model(tb)
    s0 = np.array([-0.5e-3, -0.5e-3, 0.0])
    r = np.array([0.0, 0.0, -52e-6]) + tb.masses.mass_vec * s0 / tb.body.mass
    q = rest_attitude(r)
    # CM straight below the CR: gravity torque m r x g vanishes
    assert np.allclose(quat.rotate(q, r / np.linalg.norm(r)), [0, 0, -1], atol=1e-12)
    u = np.zeros(model.nu)
    u[model.index(["s1", "s2", "s3"], "u")] = s0
    res = simulate(model, constant_input(model, u), duration=20.0, x0=model.x0(q=q),
                   p=model.params(r_x=0.0, r_y=0.0, r_z=-52e-6), noise=False)  # fmt: skip
    assert np.abs(res.x[:, model.index(["wx", "wy", "wz"])]).max() < 1e-9
    with pytest.raises(InputError, match="not below the CR"):
        rest_attitude([1e-6, 0.0, 0.0])
    with pytest.raises(InputError, match="45 deg"):
        rest_attitude([3e-6, 3e-6, -1e-7])


def test_settling_time_of_a_pd_loop_is_the_envelope_time():
    """Without an integral term the tilt loop is J theta'' + K_d theta' + (K_p + k_g) theta
    = 0: from rest at theta_r its |theta| last leaves 5 % of its peak within half a period
    of where the envelope exp(-zeta w_n t) / sqrt(1 - zeta^2) reaches 5 %."""
    from airbearing.analysis.balancing.transient import settling_time

    tb = load_testbed("platform-3dof")
    kp, kd, r_z = 1e-3, 1.8e-3, -52e-6
    k = kp - tb.body.mass * tb.gravity * r_z
    J = tb.body.inertia_matrix[1, 1]  # the y axis: the larger inertia, the slower
    wn, zeta = np.sqrt(k / J), kd / (2 * np.sqrt(k * J))
    wd = wn * np.sqrt(1 - zeta**2)
    envelope = np.log(20.0 / np.sqrt(1 - zeta**2)) / (zeta * wn)
    t = settling_time(tb, (kp, kd, 0.0), r_z, start="rest")
    assert envelope - np.pi / wd <= t <= envelope + 1e-6
    assert settling_time(tb, (kp, kd, 2e-5), r_z, start="level") == 0.0
    assert settling_time(tb, (kp, -kd, 2e-5), r_z, start="rest") == np.inf
    # started level an unstable loop does not settle either (it was reported as 0 s)
    assert settling_time(tb, (kp, -kd, 2e-5), r_z, start="level") == np.inf


def test_seed000_comparison_with_the_offset_kept_reports_the_transient():
    tb = load_testbed("platform-3dof")
    cmp = compare_methods(tb, ("mechanical", "mixed"), offsets=(-0.5e-3,), seeds=(0,),
                          free_duration=None, offset_stays=True)  # fmt: skip
    st = cmp.steady
    # the integral has to find the offset: its pole, tau = (K_p + k_g) / (K_d K_i) about
    # (1e-3 + 6.3 * 9.81 * 52e-6) / 2e-5 = 210 s, is not settled 200 s into the run
    assert st["settling_time_s"] > 2 * 210.0 and not st["steady"]
    assert f"--duration {np.ceil(st['duration_for_steady_s']):.0f}" in cmp.verdict


@pytest.mark.slow
def test_duration_sweep_marks_where_the_last_third_is_steady():
    from airbearing.analysis.balancing.comparison import parse_sweep, sweep_comparison

    # seed000-tabletop's mixed runs are still settling 200-300 s into the run (the rest
    # position's swing decays with 2 J / K_d = 33 s from 5 deg); by 600-900 s they are not
    name, values = parse_sweep("duration=300:900:2")
    sw = sweep_comparison(load_testbed("platform-3dof"), name, values, offsets=(-0.5e-3,),
                          seeds=(0, 1))  # fmt: skip
    assert [p.steady["steady"] for p in sw.points] == [False, True]
    assert len(repr(sw)) < 300 and "sweep of duration" in str(sw)
    assert list(sw.to_pandas()["duration"]) == [300.0, 900.0]
    assert sw.points[0].steady["steady_linear"]  # the linearised check alone said steady
    assert sw.points[1].ratios["slider_p2p"] < sw.points[0].ratios["slider_p2p"]


@pytest.mark.slow
def test_seed000_advantage_of_the_mixed_split():
    """The issue's check, at seed 000's conditions (Sec. 3, Tables 1-2): platform-3dof,
    seed-000 gains, 300 s from the rest position of the -0.5 and +0.5 mm offsets, 4 noise
    seeds each, 0.02 mm backlash, MTi-1 noise."""
    from airbearing.analysis.balancing.metrics import SEED000_TABLES

    tb = load_testbed("platform-3dof")
    cmp = compare_methods(tb, ("mechanical", "mixed"), seeds=(0, 1, 2, 3),
                          free_duration=None)  # fmt: skip
    # seed 000 measured 0.09 (peak-to-peak) and 0.54 (g_perp); the issue asks for at
    # least 50 % lower peak-to-peak and a g_perp_rms no worse
    assert cmp.ratios["slider_p2p"] <= 0.5, cmp.ratios
    assert cmp.ratios["g_perp_rms"] <= 1.0, cmp.ratios
    # and the levels themselves: within a factor 2 of the seed's averages (four tests
    # each; backlash, noise and the platform's vertical offset are not fully specified)
    for off, table in cmp.tables.items():
        for method in ("mechanical", "mixed"):
            ratio = table[method]["g_perp_rms"] / SEED000_TABLES[off][method]["g_perp_rms"]
            assert 0.5 <= ratio <= 2.0, (off, method, ratio)


@pytest.mark.slow
def test_seed000_offset_kept_creep_through_backlash_is_not_steady():
    """With the offset kept the integral has to find it. The linearised loop says 900 s
    is steady (settling 573 s < 600 s), but through the 20 um backlash the integral still
    creeps: the steppers' means move by tens of um between 300-600 s and 600-900 s, so the
    windowed check calls it drifting. The mixed split keeps its advantage meanwhile."""
    tb = load_testbed("platform-3dof")
    cmp = compare_methods(tb, ("mechanical", "mixed"), duration=900.0, seeds=(0, 1),
                          free_duration=None, offset_stays=True)  # fmt: skip
    st = cmp.steady
    assert st["steady_linear"] and not st["steady"], st
    assert st["metrics_window_s"] == [600.0, 900.0]
    assert any("stepper" in d and "mean moved" in d for d in st["drifting"]), st["drifting"]
    assert cmp.ratios["slider_p2p"] <= 0.5, cmp.ratios
    assert cmp.ratios["g_perp_rms"] <= 1.0, cmp.ratios


# ------------------------------------------------------------------------------ bad input


def test_mixed_needs_magnetorquers():
    tb = load_testbed("platform-3dof").replace(magnetorquers=None)
    with pytest.raises(InputError, match="magnetorquers"):
        balancing_controller(build_model(tb), "mixed")


def test_mixed_needs_nonzero_field():
    tb = load_testbed("platform-3dof").replace(field=Field(lab=(0.0, 0.0, 0.0)))
    with pytest.raises(InputError, match="field"):
        balancing_controller(build_model(tb), "mixed")


def test_unknown_method():
    with pytest.raises(InputError, match="mechanical"):
        run_balancing(load_testbed("platform-3dof"), "magic")


def test_cli_run_and_bad_input(tmp_path, capsys):
    import airbearing.cli as cli
    import airbearing.cli.balance  # noqa: F401

    out = tmp_path / "b.json"
    cli.main(["balance", "platform-3dof", "--method", "mechanical", "--duration", "30",
              "--json", str(out)])  # fmt: skip
    data = json.loads(out.read_text())
    for key in ("g_perp_rms", "g_x_rms", "g_y_rms", "dipole_rms", "residual_torque_nm"):
        assert np.isfinite(data[key])
    assert len(data["slider_p2p_m"]) == 3 and len(data["slider_std_m"]) == 3
    with pytest.raises(SystemExit) as e:
        cli.main(["balance", "cmg-yaw", "--method", "mixed", "--json", str(tmp_path / "x.json")])
    assert e.value.code == 2
    assert not (tmp_path / "x.json").exists()


def test_cli_start_and_initial_rate(tmp_path):
    import airbearing.cli as cli
    import airbearing.cli.balance  # noqa: F401

    out = tmp_path / "b.json"
    cli.main(["balance", "platform-3dof", "--method", "adaptive", "--duration", "20", "--start",
              "level", "--initial-rate", "0.01", "0", "0", "--json", str(out)])  # fmt: skip
    data = json.loads(out.read_text())
    assert data["start"] == "level" and "note" not in data and data["offset_stays"] is False
    cli.main(["balance", "platform-3dof", "--method", "adaptive", "--duration", "20",
              "--offset-stays", "--json", str(out), "--force"])  # fmt: skip
    data = json.loads(out.read_text())
    assert data["offset_stays"] is True and "nothing is learnt" in data["note"]
    # default vertical offset: 2 % of the testbed's -2.6 mm; the z slider moves it a little
    assert data["residual_offset_m"][2] == pytest.approx(0.02 * -2.6e-3, abs=1e-6)
    # a top-heavy platform has no rest position: auto starts it level and says so
    cli.main(["balance", "platform-3dof", "--duration", "20", "--vertical-offset", "1e-5",
              "--json", str(out), "--force"])  # fmt: skip
    data = json.loads(out.read_text())
    assert data["start"] == "level" and "not below the CR" in data["note"]
    for bad in (["--start", "upside-down"], ["--start", "rest", "--vertical-offset", "1e-5"]):
        with pytest.raises(SystemExit) as e:
            cli.main(["balance", "platform-3dof", "--duration", "20", "--json",
                      str(tmp_path / "x.json"), *bad])  # fmt: skip
        assert e.value.code == 2
        assert not (tmp_path / "x.json").exists()


def test_cli_methods_are_the_library_methods():
    from airbearing.cli.balance import Method
    from airbearing.design.balancing import METHODS

    assert tuple(m.value for m in Method) == tuple(METHODS)


def test_cli_infinite_time_constant_is_null_and_both_files_are_written(tmp_path):
    """A top-heavy platform (r_z > 0) has no stable tilt loop: the integral time constant
    is infinite, null in JSON, and the run still writes its log and its summary."""
    import airbearing.cli as cli

    log, out = tmp_path / "a.csv", tmp_path / "b.json"
    cli.main(["balance", "platform-3dof", "--duration", "20", "--vertical-offset", "1e-4",
              "--log", str(log), "--json", str(out)])  # fmt: skip
    data = json.loads(out.read_text())
    # K_p + k_g = 1e-3 - 6.3 kg * 9.81 m/s^2 * 1e-4 m < 0: a pole in the right half-plane
    assert data["integral_time_constant_s"] is None
    assert log.read_text().count("\n") == 1 + 20 * 20  # header + 20 s at 20 Hz


@pytest.mark.parametrize(
    "bad",
    [
        ["--duration", "nan"],
        ["--duration", "-5"],
        ["--initial-offset-mm", "inf"],
        ["--vertical-offset", "nan"],
        ["--initial-rate", "nan", "0", "0"],
        ["--method", "magic"],
        ["--start", "upside-down"],
        ["--seeds", "0", "--compare", "mechanical,mixed"],
        ["--compare", "mechanical,magic"],
        ["--sweep", "backlash=0:1:2"],
        ["--sweep", "bogus=0:1:2", "--compare", "mechanical,mixed"],
        ["--compare", "mechanical,mixed", "--log", "LOG"],
    ],
    ids=lambda b: " ".join(b),
)
def test_cli_bad_options_write_nothing(tmp_path, bad):
    import airbearing.cli as cli

    out, log = tmp_path / "x.json", tmp_path / "x.csv"
    bad = [str(log) if b == "LOG" else b for b in bad]
    with pytest.raises(SystemExit) as e:
        cli.main(["balance", "platform-3dof", "--duration", "20", "--json", str(out), *bad])
    assert e.value.code == 2
    assert not out.exists() and not log.exists()


def test_comparison_reports_progress_and_keeps_the_json_keys(tmp_path, capsys):
    from airbearing.analysis.balancing.comparison import Comparison

    calls = []

    def progress(what, done, total):
        calls.append((done, total))

    cmp = compare_methods(load_testbed("platform-3dof"), ("mechanical", "mixed"),
                          offsets=(-0.5e-3,), seeds=(0,), duration=30.0, free_duration=None,
                          progress=progress)  # fmt: skip
    assert isinstance(cmp, Comparison)
    assert calls == [(0, 2), (1, 2), (2, 2)]  # one step per run, then done
    assert set(cmp.to_json()) == {"tables", "ratios", "steady", "verdict"}

    import airbearing.cli as cli

    out = tmp_path / "c.json"
    cli.main(["balance", "platform-3dof", "--compare", "mechanical,mixed", "--seeds",
              "1", "--duration", "30", "--json", str(out)])  # fmt: skip
    data = json.loads(out.read_text())
    assert set(data) == {"tables", "ratios", "steady", "verdict"}
    assert set(data["tables"]) == {"-0.0005", "0.0005"}
    text = capsys.readouterr().out
    # the aligned table: one header and one row per offset and method
    lines = [ln for ln in text.splitlines() if "offset (mm)" in ln or ln.strip().startswith("-0.5")]
    assert len(lines) == 3 and len({len(ln) for ln in lines}) == 1, text
