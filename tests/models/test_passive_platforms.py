"""Passive platforms (no [masses] or [magnetorquers]) and attitude-only logs (no gyro).

Oracles are physics: a free rigid body keeps its energy and its lab-frame angular
momentum; a yaw rotor under viscous + quadratic drag has a closed-form spin-down; the
attitude noise of a log is white with the configured sigma (chi-square bounds).
"""

import json

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from airbearing import quaternion as quat
from airbearing.analysis.simulation.artefacts import sample_times, with_gap, with_jitter
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.analysis.simulation.scenarios import free_oscillation, free_summary, spindown
from airbearing.errors import InputError
from airbearing.io.testbed import testbed_from_dict as make_testbed
from airbearing.models.effects import REGISTRY, WHEEL_EFFECTS, applicable_effects
from airbearing.models.model import build_model

# seed 004: the 6.3 kg platform, its J_CR and offset r^o (the values of the platform built-in)
J3 = [[0.0241, -0.001, 0.0], [-0.001, 0.0332, -0.004], [0.0, -0.004, 0.0363]]
R3 = [0.0004, 0.0007, -0.0026]


def passive3(*, cm_offset=R3, gyro=True, attitude_noise=0.0, field=None):
    d = {
        "kind": "platform",
        "name": "passive-3dof",
        "gravity": 9.81,
        "body": {"dof": 3, "mass": 6.3, "inertia": J3, "cm_offset": list(cm_offset)},
        "sensors": {
            "rate": 20.0,
            "gyro_noise": 4e-4,
            "gyro": gyro,
            "attitude_noise": attitude_noise,
        },
    }
    if field is not None:
        d["field"] = {"lab": list(field)}
    return make_testbed(d)


def passive1(*, gyro=False, attitude_noise=1e-3, rate=10.0):
    # a CubeSat mock-up on a yaw bearing, motion capture at 10 Hz (issue 13's real case)
    return make_testbed(
        {
            "kind": "platform",
            "name": "mocap-yaw",
            "gravity": 9.81,
            "body": {"dof": 1, "mass": 4.2, "inertia": 0.05},
            "sensors": {
                "rate": rate,
                "gyro": gyro,
                "attitude_noise": attitude_noise,
                "gyro_noise": 2e-4,
            },
        }
    )


# ------------------------------------------------------------------------------ model


@pytest.mark.parametrize("dof", [1, 3])
def test_passive_platform_has_no_actuator_in_its_physics(dof):
    tb = passive3() if dof == 3 else passive1()
    m = build_model(tb)
    assert not {"m_1", "m_2", "m_3"} & set(m.p_names)
    # the input layout of a platform stays, so callers index s1..s3, mx..mz as anywhere
    assert m.u_names[:6] == ("s1", "s2", "s3", "mx", "my", "mz")
    x = ca.SX.sym("x", m.nx)
    u = ca.SX.sym("u", m.nu)
    dep = ca.jacobian(m.f(x, u, m.p0), u[:6])
    assert dep.nnz() == 0  # structurally: no slider or dipole term at all


def test_passive_dof1_is_a_yaw_rotor():
    tb = passive1()
    m = build_model(tb)
    assert m.x_names == ("yaw", "wz") and m.p_names == ("J_zz", "mass", "gravity")
    # no torque: yaw grows linearly; RK4 integrates a constant rate exactly
    log = simulate_on_times(tb, sample_times(tb, 10.0), initial_rate=1.5, yaw0=0.2, noise=False)
    assert_allclose(log.data["true_yaw"], 0.2 + 1.5 * log.t, rtol=0, atol=1e-12)
    assert_allclose(log.data["true_wz"], 1.5, rtol=0, atol=0)


def test_passive_dof1_on_a_spring_is_a_harmonic_oscillator():
    """Cables on a yaw bearing: J yaw'' = -k yaw, yaw = y0 cos(W t) + (w0 / W) sin(W t)."""
    tb = passive1()
    k, J = 2e-3, 0.05  # N m / rad, kg m^2: W = 0.2 rad/s, period 31 s
    t = with_jitter(sample_times(tb, 60.0), 0.3, seed=8)
    log = simulate_on_times(tb, t, initial_rate=0.1, yaw0=0.5, noise=False,
                            effects={"spring_torque": k})  # fmt: skip
    W = np.sqrt(k / J)
    yaw = 0.5 * np.cos(W * t) + 0.1 / W * np.sin(W * t)
    # RK4 at h <= 37.5 ms on W = 0.2 rad/s: phase error ~ (h W)^4 W t / 120 ~ 1e-11 rad
    assert_allclose(log.column("true_yaw"), yaw, rtol=0, atol=1e-10)


def test_residual_dipole_on_a_passive_platform_sees_the_logged_field():
    """tau = m_res x b_body with b the input (logged) field, not the [field] table's value."""
    tb = passive3(cm_offset=(0, 0, 0), field=(0, 0, 6e-4))
    m = build_model(tb, {"residual_dipole": (0.05, 0.0, 0.0)})
    u = np.zeros(m.nu)
    u[m.index(["bx_lab", "by_lab", "bz_lab"], "u")] = [0.0, 2e-4, 0.0]  # not the table's
    w_dot = np.asarray(m.f(m.x0(), u, m.p0)).ravel()[4:7]
    # level body = lab axes: (0.05, 0, 0) x (0, 2e-4, 0) = (0, 0, 1e-5) N m
    assert_allclose(np.asarray(J3) @ w_dot, [0, 0, 1e-5], rtol=1e-12, atol=1e-20)


def test_effects_that_act_on_a_passive_platform():
    # FORMATS.md table: everything but the CMG dead zone and the wheel effects (no
    # [wheels]); the spring on dof 1 only; the CM offset error on dof 3 only; rate-sensor
    # effects only with a gyro
    assert set(applicable_effects("platform", 3, True)) == set(REGISTRY) - {
        "spring_torque",
        "yaw_imbalance",
        "gimbal_deadzone",
        *WHEEL_EFFECTS,
    }
    assert set(applicable_effects("platform", 1, True, gyro=False)) == set(REGISTRY) - {
        "cm_offset_error",
        "gimbal_deadzone",
        "gyro_bias",
        "sensor_lag",
        *WHEEL_EFFECTS,
    }
    values = {
        "cm_offset_error": (1e-5, 0, 0),
        "residual_dipole": (0.01, 0, 0),
        "yaw_imbalance": (1e-4, 0),
    }
    for dof, tb in ((3, passive3(field=(0, 0, 6e-4))), (1, passive1(gyro=True))):
        for name in applicable_effects("platform", dof, True):
            m = build_model(tb, {name: values.get(name, 1e-3)})
            assert m.p_names[-1].startswith(name)
    with pytest.raises(InputError, match="no rate sensor"):
        build_model(passive1(gyro=False), {"sensor_lag": 0.05})
    with pytest.raises(InputError, match="no rate sensor"):
        build_model(passive3(gyro=False), {"gyro_bias": 1e-3})


# ------------------------------------------------------------------------------ conservation


def _lab_momentum_and_energy(log, J, r, m_g):
    q = log.columns(["true_qw", "true_qx", "true_qy", "true_qz"])
    w = log.columns(["true_wx", "true_wy", "true_wz"])
    L_lab = quat.rotate(q, w @ np.asarray(J).T)
    kinetic = 0.5 * np.einsum("ni,ij,nj->n", w, np.asarray(J), w)
    potential = m_g * quat.rotate(q, np.asarray(r, float))[:, 2]  # CM height x m g
    return L_lab, kinetic + potential


def test_passive_dof3_free_body_conserves_energy_and_lab_momentum():
    """No offset, no effects: torque-free, so E and the whole vector R(q) J w stay constant."""
    tb = passive3(cm_offset=(0, 0, 0))
    t = with_jitter(sample_times(tb, 60.0), 0.3, seed=5)  # on jittered times too
    log = simulate_on_times(
        tb, t, initial_rate=(0.3676, 0.1265, -1.4835), q0=quat.qexp([0.05, -0.03, 0.2]),
        noise=False, substeps=8,
    )  # fmt: skip
    L, E = _lab_momentum_and_energy(log, J3, (0, 0, 0), 0.0)
    # RK4, h <= 1.3 dt / 8 = 8 ms, |w| 1.5 rad/s: local error ~ (h w)^5 / 120 ~ 1e-13,
    # over 1200 steps ~1e-10 (measured 3e-13 on E, 1.3e-11 on L); bound 1e-9
    assert np.max(np.abs(E - E[0])) / E[0] < 1e-9
    assert np.max(np.linalg.norm(L - L[0], axis=1)) / np.linalg.norm(L[0]) < 1e-9
    q = log.columns(["true_qw", "true_qx", "true_qy", "true_qz"])
    assert np.max(np.abs(np.linalg.norm(q, axis=1) - 1)) < 1e-12  # renormalised each step


def test_passive_dof3_pendulum_conserves_energy_and_vertical_momentum():
    """With the CM offset gravity acts: E (kinetic + m g z_cm) and the lab-z momentum stay."""
    tb = passive3()
    r = free_oscillation(tb, initial_rate=(-0.48, 0.09, -1.62), duration=60.0, noise=False)
    assert r.log.has("qw", "wx") and not r.log.has("s1") and not r.log.has("mx")
    L, E = _lab_momentum_and_energy(r.log, J3, R3, 6.3 * 9.81)
    scale = 0.5 * 1.62**2 * 0.0363  # the spin's kinetic energy, J
    # RK4 at dt / 4 = 12.5 ms on a 2.3 rad/s pendulum and a 1.7 rad/s spin: measured drift
    # 2.4e-8 of the spin energy and 1.4e-9 of |L|; bounds 4x and 7x above that
    assert np.max(np.abs(E - E[0])) / scale < 1e-7
    assert np.max(np.abs(L[:, 2] - L[0, 2])) / np.linalg.norm(L[0]) < 1e-8
    assert free_summary(r)["max_tilt_deg"] > 1.0  # it did swing: the test can fail


# ------------------------------------------------------------------------------ spin-down


def test_spindown_matches_closed_form_on_jittered_times_with_a_gap():
    """J w' = -c w - k w^2 (w > 0): w = a w0 e^-at / (a + b w0 (1 - e^-at)), a = c/J, b = k/J.

    The yaw is its integral: yaw = yaw0 + ln(1 + b w0 (1 - e^-at) / a) / b.
    """
    tb = passive1()
    c = k = 3.5e-5  # N m s, N m s^2: the hidden effects of issue 13's motion-capture case
    t = with_jitter(sample_times(tb, 400.0), 0.2, seed=2)
    t, after = with_gap(t, 150.0, 20.0)
    log = simulate_on_times(
        tb, t, initial_rate=4.0, yaw0=0.3, noise=False,
        effects={"viscous_friction": c, "aero_drag": k},
    )  # fmt: skip
    a, b, w0 = c / 0.05, k / 0.05, 4.0  # J = 0.05 kg m^2
    e = np.exp(-a * t)
    w = a * w0 * e / (a + b * w0 * (1 - e))
    yaw = 0.3 + np.log(1 + b * w0 * (1 - e) / a) / b
    # RK4 with h <= 1.5 dt / 4 = 37.5 ms on a decay rate of at most (a + 2 b w0) = 6e-3 1/s:
    # truncation ~ (h rate)^5 per step ~ 1e-17; left: rounding over ~10^4 steps (measured
    # 5e-15 relative on w, 6e-12 rad on a yaw of 1000 rad)
    assert_allclose(log.data["true_wz"], w, rtol=1e-12)
    assert_allclose(log.data["true_yaw"], yaw, rtol=0, atol=1e-10)
    assert log.t[after] - log.t[after - 1] > 20.0  # the gap is in the log


def test_spindown_scenario_on_passive_dof1_and_dof3():
    r1 = spindown(passive1(gyro=True), initial_rate=2.0, duration=30.0,
                  effects={"coulomb_friction": 1e-3}, seed=1)  # fmt: skip
    # Coulomb friction alone: w decreases linearly at f / J = 0.02 rad/s^2
    w = r1.state("wz")
    assert_allclose(w, 2.0 - 0.02 * r1.t, rtol=0, atol=1e-9)
    assert r1.log.has("yaw", "wz")
    r3 = spindown(passive3(), initial_rate=1.0, duration=5.0, effects={"aero_drag": 1e-4})
    s = free_summary(r3)
    assert s["final_rate_deg_s"] < s["peak_rate_deg_s"]


def test_passive_scenarios_refuse_sliders_and_off_axis_rates_on_dof1():
    with pytest.raises(InputError, match="passive"):
        free_oscillation(passive3(), sliders=(0.001, 0, 0), duration=1.0)
    with pytest.raises(InputError, match="dof = 1"):
        free_oscillation(passive1(), initial_rate=(0.1, 0, 1.0), duration=1.0)
    with pytest.raises(InputError, match="dof = 1"):
        spindown(passive1(), q0=(0.0, 0.0, 0.0, 1.0), duration=1.0)
    with pytest.raises(InputError, match="no \\[masses\\]"):
        simulate_on_times(passive3(), sample_times(passive3(), 1.0), inputs={"s1": 0.001})


# ------------------------------------------------------------------------------ attitude only


def _chi2_bounds(dof, p=1e-6):
    """Two-sided chi-square interval of probability 1 - 2p (the test's false-alarm rate)."""
    return stats.chi2.ppf(p, dof), stats.chi2.ppf(1 - p, dof)


def test_attitude_only_dof3_log_has_no_rates_and_its_noise_has_the_configured_sigma():
    sigma = 1e-3
    tb = passive3(gyro=False, attitude_noise=sigma)
    r = free_oscillation(tb, initial_rate=(-0.48, 0.09, -1.62), duration=60.0, seed=4)
    cols = set(r.log.data.columns)
    assert {"qw", "qx", "qy", "qz"} <= cols
    assert not cols & {"wx", "wy", "wz", "gx", "gy", "gz", "s1", "mx"}
    q_true = r.log.columns(["true_qw", "true_qx", "true_qy", "true_qz"])
    dq = quat.qmul(quat.qconj(q_true), r.log.quaternions())  # body-side error rotation
    rotvec = 2 * dq[:, 1:4] * np.sign(dq[:, :1])  # small angles: 2 x vector part
    n = rotvec.size  # 3 axes x 1200 samples, each N(0, sigma^2) by FORMATS.md
    lo, hi = _chi2_bounds(n)
    assert lo < np.sum((rotvec / sigma) ** 2) < hi
    for axis in range(3):  # white per axis, none left out
        lo, hi = _chi2_bounds(len(rotvec))
        assert lo < np.sum((rotvec[:, axis] / sigma) ** 2) < hi


def test_attitude_only_dof1_log_on_given_times():
    sigma = 1e-3
    tb = passive1(attitude_noise=sigma)
    t, _ = with_gap(with_jitter(sample_times(tb, 100.0), 0.2, seed=1), 40.0, 10.0)
    log = simulate_on_times(tb, t, initial_rate=3.0, effects={"aero_drag": 3.5e-5}, seed=9)
    assert set(log.data.columns) == {"t", "yaw", "true_yaw", "true_wz"}
    e = log.column("yaw") - log.column("true_yaw")
    lo, hi = _chi2_bounds(e.size)
    assert lo < np.sum((e / sigma) ** 2) < hi
    # the seed is explicit: the same inputs give the same log, another seed another one
    again = simulate_on_times(tb, t, initial_rate=3.0, effects={"aero_drag": 3.5e-5}, seed=9)
    other = simulate_on_times(tb, t, initial_rate=3.0, effects={"aero_drag": 3.5e-5}, seed=10)
    assert_allclose(again.column("yaw"), log.column("yaw"), rtol=0, atol=0)
    assert not np.allclose(other.column("yaw"), log.column("yaw"), rtol=0, atol=sigma / 10)


def test_attitude_noise_override_and_noise_free():
    tb = passive1(attitude_noise=1e-3)
    r = free_oscillation(tb, initial_rate=(0, 0, 1.0), duration=5.0, attitude_noise=0.0)
    assert_allclose(r.log.column("yaw"), r.log.column("true_yaw"), rtol=0, atol=0)
    with pytest.raises(InputError, match="attitude noise"):
        free_oscillation(tb, initial_rate=(0, 0, 1.0), duration=5.0, attitude_noise=-1.0)


# ------------------------------------------------------------------------------ CLI


def test_cli_spindown_of_a_motion_capture_rig(tmp_path):
    from cli_run import run

    from airbearing.io.log import read_log
    from airbearing.io.testbed import write_testbed

    tb = passive1(attitude_noise=1e-3)
    path = write_testbed(tb, tmp_path / "rig.toml")
    log, js = tmp_path / "spin.csv", tmp_path / "spin.json"
    args = ["simulate", str(path), "--scenario", "spindown", "--spin-rate", "4", "--duration",
            "40", "--effect", "aero_drag=3.5e-5", "-o", str(log), "--json", str(js)]  # fmt: skip
    assert run(args) == 0
    back = read_log(log, tb)
    assert {"t", "yaw"} <= set(back.data.columns) and not back.has("wz")
    # w' = -(k/J) w^2: w(t) = 4 / (1 + 4 k t / J) (closed form of quadratic drag)
    final = 4 / (1 + 4 * 3.5e-5 * back.t[-1] / 0.05)
    assert back.column("true_wz")[-1] == pytest.approx(final, rel=1e-6)  # RK4 at 25 ms: ~1e-12
    assert json.loads(js.read_text())["scenario"] == "spindown"
    bad = tmp_path / "bad.csv"
    assert run(["simulate", str(path), "--scenario", "spindown", "--effect", "gyro_bias=0.01",
                "-o", str(bad)]) == 2  # fmt: skip
    assert not bad.exists()


def test_slew_refuses_a_testbed_without_gyro():
    from dataclasses import replace

    from airbearing.analysis.simulation.scenarios import slew
    from airbearing.io.testbed import load_testbed

    cmg = load_testbed("cmg-yaw")
    no_gyro = cmg.replace(sensors=replace(cmg.sensors, gyro=False))
    with pytest.raises(InputError, match="gyro"):
        slew(no_gyro, angle_deg=90, duration=1.0)
