"""The reaction-wheel Model (models/wheels.py) against analytic oracles.

* total angular momentum in the lab frame ``R(q) (J w + sum Iw_i W_i a_i)`` is conserved
  without external torque while the wheels exchange momentum with the body (FORMATS:
  ``dH/dt + w x H = tau``);
* the Model's derivative solves the two FORMATS equations (momentum balance and each
  wheel's axis) as one joint linear system, solved here in NumPy (a different method
  from the Model's elimination through ``J_eff``);
* a wheel's free spin-down: an exponential under viscous friction, a ramp under Coulomb
  friction, with the rates derived in models/wheels.py;
* the dof-1 Model is the dof-3 Model turning about z only;
* the torque and speed limits, and a speed-commanded wheel's first-order response.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.testbed import Body, Wheels, load_testbed
from airbearing.models.effects import REGISTRY, applicable_effects
from airbearing.models.model import build_model
from airbearing.models.wheels import SPEED_LIMIT_BAND

J3 = np.array([[0.06, 0.004, -0.002], [0.004, 0.065, 0.003], [-0.002, 0.003, 0.08]])
S3 = 1 / math.sqrt(3)


def _free_3axis(**wheels):
    """rw-3axis with products of inertia, no field and CM on the CR: no external torque."""
    tb = load_testbed("rw-3axis")
    body = Body(dof=3, mass=5.0, inertia=tuple(map(tuple, J3)))
    if wheels:
        w = tb.wheels
        fields = {k: getattr(w, k) for k in ("axes", "inertia", "max_torque", "max_speed")}
        fields.update(wheels)
        return tb.replace(body=body, field=None, wheels=Wheels(**fields))
    return tb.replace(body=body, field=None)


def _yaw(**wheels):
    tb = load_testbed("rw-yaw")
    if not wheels:
        return tb
    w = tb.wheels
    fields = {k: getattr(w, k) for k in ("axes", "inertia", "max_torque", "max_speed")}
    fields.update(wheels)
    return tb.replace(wheels=Wheels(**fields))


def _lab_momentum(tb, X):
    A, Iw = tb.wheels.axes_matrix, tb.wheels.inertia_vec
    H = X[:, 4:7] @ tb.body.inertia_matrix.T + (X[:, 7 : 7 + len(Iw)] * Iw) @ A
    return quat.rotate(X[:, 0:4], H)


def _rollout(m, x0, U, dt, substeps=4):
    return np.vstack([x0, np.asarray(m.rollout(U.shape[1], dt, substeps)(x0, U, m.p0)).T])


def test_lab_momentum_is_conserved_while_wheels_exchange_it():
    tb = _free_3axis()
    m = build_model(tb)
    n, dt = 200, tb.sensors.dt
    rng = np.random.default_rng(1)
    U = np.zeros((m.nu, n))
    U[m.index(["wc1", "wc2", "wc3", "wc4"], "u")] = np.repeat(
        rng.uniform(-8e-4, 8e-4, (4, n // 10)), 10, axis=1
    )
    x0 = m.x0(w=[0.05, -0.03, 0.08], wheels=[100.0, -50.0, 30.0, 200.0])
    X = _rollout(m, x0, U, dt, substeps=8)
    # the wheels did exchange momentum: their speeds moved by tens of rad/s
    assert np.max(np.abs(X[-1, 7:11] - x0[7:11])) > 10.0
    L = _lab_momentum(tb, X)
    # 1e-12: RK4 on rates of 0.1 rad/s with 6 ms sub-steps has a local error far below
    # that (3e-14 measured); a wrong reaction sign or a missing w x h_w term breaks it at
    # the size of the wheels' momentum (1e-2 relative)
    assert np.max(np.abs(L - L[0])) / np.linalg.norm(L[0]) < 1e-12


def _joint_solve(tb, x, u, effects):
    """dw/dt and dW/dt from FORMATS' equations as one linear system (NumPy)."""
    wh = tb.wheels
    n = wh.n
    A = wh.axes_matrix
    scale = 1 + np.broadcast_to(effects.get("wheel_inertia_error", 0.0), (n,))
    Iw = wh.inertia_vec * scale
    gain = 1 + np.broadcast_to(effects.get("wheel_torque_error", 0.0), (n,))
    w, W = x[4:7], x[7 : 7 + n]
    c = u[12 : 12 + n]
    tau_m = gain * np.clip(c, -wh.max_torque, wh.max_torque)
    tau_f = np.broadcast_to(effects.get("wheel_viscous_friction", 0.0), (n,)) * W
    tau_f = tau_f + np.broadcast_to(effects.get("wheel_coulomb_friction", 0.0), (n,)) * np.tanh(
        W / 0.1  # FORMATS: smoothed within about 0.1 rad/s
    )
    J = tb.body.inertia_matrix
    H = J @ w + A.T @ (Iw * W)
    M = np.block([[J, A.T * Iw], [Iw[:, None] * A, np.diag(Iw)]])
    rhs = np.concatenate([-np.cross(w, H), tau_m - tau_f])
    sol = np.linalg.solve(M, rhs)
    return sol[:3], sol[3:]


@pytest.mark.parametrize(
    "effects",
    [
        {},
        {"wheel_viscous_friction": 2e-6, "wheel_coulomb_friction": [1e-5, 2e-5, 0.0, 3e-5]},
        {"wheel_torque_error": [0.1, -0.05, 0.2, 0.0], "wheel_inertia_error": -0.2},
    ],
    ids=["nominal", "friction", "torque-and-inertia-errors"],
)
def test_derivative_solves_the_formats_equations(effects):
    tb = _free_3axis()
    m = build_model(tb, effects)
    rng = np.random.default_rng(7)
    for _ in range(5):
        x = m.x0(q=quat.qexp(rng.normal(size=3)), w=rng.normal(scale=0.3, size=3))
        x[7:11] = rng.uniform(-300, 300, 4)
        u = np.zeros(m.nu)
        u[12:16] = rng.uniform(-1.5e-3, 1.5e-3, 4)  # some beyond max_torque = 1e-3
        f = np.asarray(m.f(x, u, m.p0)).ravel()
        w_dot, W_dot = _joint_solve(tb, x, u, effects)
        # 1e-12 relative: the same equations solved two ways (condition number ~ 1e3)
        assert_allclose(f[4:7], w_dot, rtol=1e-12, atol=1e-12 * np.max(np.abs(w_dot)))
        assert_allclose(f[7:11], W_dot, rtol=1e-12, atol=1e-12 * np.max(np.abs(W_dot)))
        assert_allclose(f[0:4], quat.qdot(x[0:4], x[4:7]), rtol=1e-14, atol=1e-16)


def test_viscous_spin_down_is_an_exponential_with_the_reduced_inertia():
    # dof 1, one wheel, body free: dW/dt = -c W (1/Iw + 1/(J - Iw)) (models/wheels.py)
    tb = _yaw().with_effects({"wheel_viscous_friction": 1e-6})
    m = build_model(tb)
    J, Iw, c = tb.body.yaw_inertia, tb.wheels.inertia[0], 1e-6
    rate = c * J / (Iw * (J - Iw))
    n, dt = 400, tb.sensors.dt
    x0 = m.x0(w=0.1, wheels=[400.0])
    X = _rollout(m, x0, np.zeros((m.nu, n)), dt)
    t = dt * np.arange(n + 1)
    W = 400.0 * np.exp(-rate * t)
    # RK4 error (rate x h)^5 / 120 per step with rate h = 4e-4: nothing at 1e-10
    assert_allclose(X[:, 2], W, rtol=1e-10)
    H0 = J * 0.1 + Iw * 400.0
    assert_allclose(X[:, 1], (H0 - Iw * W) / J, rtol=1e-10)  # J wz + Iw W is constant


def test_coulomb_spin_down_is_a_ramp():
    f = 2e-5
    tb = _yaw().with_effects({"wheel_coulomb_friction": f})
    m = build_model(tb)
    J, Iw = tb.body.yaw_inertia, tb.wheels.inertia[0]
    slope = f * (1 / Iw + 1 / (J - Iw))  # rad/s^2
    n, dt = 200, tb.sensors.dt
    X = _rollout(m, m.x0(wheels=[200.0]), np.zeros((m.nu, n)), dt)
    t = dt * np.arange(n + 1)
    assert X[-1, 2] > 5.0  # still far outside the 0.1 rad/s smoothing: tanh = 1 to 1e-40
    assert_allclose(X[:, 2], 200.0 - slope * t, rtol=1e-12)
    assert_allclose(X[:, 1], -Iw * (X[:, 2] - 200.0) / J, rtol=1e-9, atol=1e-15)


def test_dof1_model_is_the_dof3_model_about_z():
    wheels = {"axes": [[0, 0, 1], [0, 0, -1]], "inertia": [3e-5, 2e-5], "max_torque": 1e-3,
              "max_speed": 600.0}  # fmt: skip
    J = np.diag([0.05, 0.06, 0.02])
    tb3 = load_testbed("rw-3axis").replace(
        body=Body(dof=3, mass=3.0, inertia=tuple(map(tuple, J))),
        field=None,
        magnetorquers=None,
        wheels=Wheels(**wheels),
    )
    tb1 = load_testbed("rw-yaw").replace(wheels=Wheels(**wheels))
    tb1 = tb1.replace(body=Body(dof=1, mass=3.0, inertia=0.02))
    m3, m1 = build_model(tb3), build_model(tb1)
    n, dt = 200, 0.05
    rng = np.random.default_rng(3)
    cmd = np.repeat(rng.uniform(-9e-4, 9e-4, (2, n // 10)), 10, axis=1)
    U3, U1 = np.zeros((m3.nu, n)), np.zeros((m1.nu, n))
    U3[m3.index(["wc1", "wc2"], "u")] = cmd
    U1[m1.index(["wc1", "wc2"], "u")] = cmd
    X3 = _rollout(m3, m3.x0(w=[0, 0, 0.05], wheels=[50.0, -20.0]), U3, dt)
    X1 = _rollout(m1, m1.x0(w=0.05, wheels=[50.0, -20.0]), U1, dt)
    yaw3 = np.unwrap(2 * np.arctan2(X3[:, 3], X3[:, 0]))
    # 1e-10: the same arithmetic except the quaternion path (renormalised each sample)
    assert_allclose(yaw3, X1[:, 0], rtol=0, atol=1e-10)
    assert_allclose(X3[:, 6], X1[:, 1], rtol=1e-10, atol=1e-14)
    assert_allclose(X3[:, 7:9], X1[:, 2:4], rtol=1e-10)
    assert np.max(np.abs(X3[:, 4:6])) < 1e-15  # no tilt rate appears


def test_torque_limit():
    tb = _yaw()
    m = build_model(tb)
    J, Iw, tmax = tb.body.yaw_inertia, tb.wheels.inertia[0], tb.wheels.max_torque
    for command, applied in ((5 * tmax, tmax), (-3 * tmax, -tmax), (0.4 * tmax, 0.4 * tmax)):
        u = np.zeros(m.nu)
        u[m.index("wc1", "u")[0]] = command
        f = np.asarray(m.f(m.x0(wheels=[10.0]), u, m.p0)).ravel()
        # the body turns the other way: J_eff dwz/dt = -tau_m
        assert_allclose(f[1], -applied / (J - Iw), rtol=1e-14)


def test_speed_limit():
    tb = _yaw()
    m = build_model(tb)
    Wmax, tmax = tb.wheels.max_speed, tb.wheels.max_torque
    J, Iw = tb.body.yaw_inertia, tb.wheels.inertia[0]
    i_wc = m.index("wc1", "u")[0]

    def wz_dot(W, command):
        u = np.zeros(m.nu)
        u[i_wc] = command
        return float(np.asarray(m.f(m.x0(wheels=[W]), u, m.p0)).ravel()[1])

    full = -tmax / (J - Iw)
    assert wz_dot(Wmax, tmax) == 0.0  # no torque that speeds the wheel up at the limit
    assert wz_dot(-Wmax * 1.01, -tmax) == 0.0
    assert wz_dot(Wmax, -tmax) == pytest.approx(-full, rel=1e-14)  # slowing: never cut
    assert wz_dot(Wmax * (1 - SPEED_LIMIT_BAND / 2), tmax) == pytest.approx(full / 2, rel=1e-9)
    assert wz_dot(Wmax * (1 - 2 * SPEED_LIMIT_BAND), tmax) == pytest.approx(full, rel=1e-14)
    # driven at full torque from near the limit for 10 s: the wheel never passes it
    n = 200
    U = np.zeros((m.nu, n))
    U[i_wc] = tmax
    X = _rollout(m, m.x0(wheels=[0.97 * Wmax]), U, tb.sensors.dt)
    assert X[-1, 2] > (1 - SPEED_LIMIT_BAND) * Wmax
    assert np.max(X[:, 2]) <= Wmax


def test_speed_command_is_a_first_order_response():
    # J_eff dwz/dt = -g, dW/dt = g/Iw + g/J_eff with g = Iw (u - W)/tau:
    # dW/dt = (u - W)/tau_eff, tau_eff = tau (J - Iw)/J (models/wheels.py)
    tb = _yaw(command="speed", speed_loop_tau=0.2, max_torque=0.05)
    m = build_model(tb)
    J, Iw = tb.body.yaw_inertia, tb.wheels.inertia[0]
    tau_eff = 0.2 * (J - Iw) / J
    n, dt = 40, tb.sensors.dt
    U = np.zeros((m.nu, n))
    U[m.index("wc1", "u")[0]] = 300.0  # request Iw 300/0.2 = 0.043 N m < max_torque
    X = _rollout(m, m.x0(wheels=[0.0]), U, dt, substeps=16)
    t = dt * np.arange(n + 1)
    # RK4 with h/tau_eff = 0.016: local error ~ 1e-11 relative
    assert_allclose(X[:, 2], 300.0 * (1 - np.exp(-t / tau_eff)), rtol=1e-8, atol=1e-9)
    assert_allclose(X[:, 1], -Iw * X[:, 2] / J, rtol=1e-8, atol=1e-15)  # momentum shared


def test_x0_takes_the_testbeds_wheel_speeds():
    tb = _free_3axis(speeds=[1.0, 2.0, 3.0, 4.0])
    m = build_model(tb)
    assert_allclose(m.x0()[m.index(["W1", "W2", "W3", "W4"])], [1, 2, 3, 4])
    assert_allclose(m.x0(wheels=[0, 0, 0, 5])[m.index("W4")], [5])


def test_names_of_the_wheel_model():
    tb = load_testbed("rw-3axis")
    m = build_model(tb, {"wheel_viscous_friction": 1e-6, "wheel_torque_error": [0.1] * 4})
    assert m.x_names[7:] == ("W1", "W2", "W3", "W4")
    assert m.u_names[12:] == ("wc1", "wc2", "wc3", "wc4")
    assert m.y_names[10:] == ("ws1", "ws2", "ws3", "ws4")
    i = m.p_names.index("Iw_1")
    assert m.p_names[i : i + 4] == ("Iw_1", "Iw_2", "Iw_3", "Iw_4")
    assert m.p_names[i + 4 :] == (
        "wheel_viscous_friction",
        "wheel_torque_error_1",
        "wheel_torque_error_2",
        "wheel_torque_error_3",
        "wheel_torque_error_4",
    )
    assert_allclose(m.p0[i : i + 4], tb.wheels.inertia_vec)


def test_wheel_effects_are_refused_without_wheels_and_torque_error_on_speed_wheels():
    wheel_effects = [n for n in REGISTRY if n.startswith("wheel_")]
    assert not set(wheel_effects) & set(applicable_effects("platform", 3, True))
    assert set(wheel_effects) <= set(applicable_effects("platform", 3, True, True, "torque"))
    speed = applicable_effects("platform", 1, True, True, "speed")
    assert "wheel_torque_error" not in speed and "wheel_viscous_friction" in speed
    with pytest.raises(InputError, match="has no \\[wheels\\]"):
        build_model(load_testbed("seed004-platform"), {"wheel_coulomb_friction": 1e-5})
    with pytest.raises(InputError, match="speed-commanded"):
        build_model(_yaw(command="speed", speed_loop_tau=0.1), {"wheel_torque_error": 0.1})
    with pytest.raises(InputError, match="list of 4 numbers"):
        build_model(load_testbed("rw-3axis"), {"wheel_inertia_error": [0.1, 0.2]})


def test_wheel_values_are_run_values_of_one_structure():
    # Iw, the initial speeds and the speed noise enter as p, x0 and noise: one compiled
    # structure serves dispersed wheels, and gives what a freshly built Model gives
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.models.structure_cache import model_for, structure_key

    tb = _yaw().with_effects({"wheel_viscous_friction": 1e-6})
    variants = [
        tb.replace(wheels=Wheels(**{**tb.wheels.__dict__, "inertia": iw, "speeds": w0,
                                    "speed_noise": sn}))
        for iw, w0, sn in ((2e-5, 300.0, 0.01), (4e-5, 100.0, 0.02))
    ]  # fmt: skip
    assert structure_key(variants[0]) == structure_key(variants[1])
    assert structure_key(variants[0]) != structure_key(_yaw(max_torque=2e-3))
    for t in variants:
        shared = free_oscillation(t, duration=1.0, model=model_for(t), seed=3).log.data
        fresh = free_oscillation(t, duration=1.0, seed=3).log.data
        assert_allclose(shared["ws1"], fresh["ws1"], rtol=0, atol=0)  # the same arithmetic
        assert shared["true_W1"].iloc[0] == t.wheels.speeds[0]
