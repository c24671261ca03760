"""Physics of the Model: CMG momentum and Jacobian, gravity torque, conservation laws, effects."""

import casadi as ca
import numpy as np
import pytest
from numpy.testing import assert_allclose

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.io.testbed import Body, load_testbed
from airbearing.io.vocabulary import EFFECTS
from airbearing.models.cmg import cmg_functions, jacobian_eq15
from airbearing.models.effects import REGISTRY, applicable_effects
from airbearing.models.model import build_model


@pytest.fixture(scope="module")
def platform():
    return load_testbed("platform-3dof")


@pytest.fixture(scope="module")
def cmg():
    return load_testbed("cmg-yaw")


def test_cmg_jacobian_equals_seed001_eq15():
    fns = cmg_functions()
    rng = np.random.default_rng(1)
    for beta in np.deg2rad([53.13, 54.73, 30.0]):
        for _ in range(20):
            d = rng.uniform(-np.pi, np.pi, 4)
            # exact: CasADi differentiates eq. 12 symbolically; eq. 15 is its closed form
            assert_allclose(np.asarray(fns["A"](d, beta)), jacobian_eq15(d, beta), atol=1e-14)


def test_cmg_momentum_at_zero_gimbals():
    # seed 001 eq. 12 at delta = 0: the four rotors cancel pairwise, h = 0
    assert_allclose(np.asarray(cmg_functions()["H"](np.zeros(4), 0.95)).ravel(), 0, atol=1e-15)


def test_registry_names_the_whole_vocabulary():
    # STYLE.md: one registry a test walks through, so forgetting to register fails loudly
    assert list(REGISTRY) == list(EFFECTS)


def test_gravity_torque_by_hand(platform):
    # tilt the platform 10 deg about body x; offset r = (0, 0, -2.6 mm):
    # tau = m r x g_body, |tau| = m g |r_z| sin(10 deg) about x, restoring (pendulous)
    tb = platform.replace(
        body=Body(dof=3, mass=6.3, inertia=platform.body.inertia, cm_offset=(0.0, 0.0, -0.0026))
    )
    m = build_model(tb)
    q = quat.from_axis_angle([1, 0, 0], np.deg2rad(10))
    x = m.x0(q=q)
    xdot = np.asarray(m.f(x, np.zeros(m.nu), m.p0)).ravel()
    J = tb.body.inertia_matrix
    tau = J @ xdot[4:7]
    expected = -6.3 * 9.81 * 0.0026 * np.sin(np.deg2rad(10))
    assert_allclose(tau, [expected, 0, 0], rtol=1e-12, atol=1e-15)


def test_slider_moves_cm_and_adds_inertia(platform):
    # FORMATS.md / seed 004 eqs. 4-7: slider 1 at s moves the CM by m1 s u1 / M
    m = build_model(platform)
    s = 0.02
    u = np.zeros(m.nu)
    u[m.index("s1", "u")[0]] = s
    q = quat.from_axis_angle([0, 1, 0], np.deg2rad(5))
    x = m.x0(q=q)
    w_dot0 = np.asarray(m.f(x, np.zeros(m.nu), m.p0)).ravel()[4:7]
    w_dot1 = np.asarray(m.f(x, u, m.p0)).ravel()[4:7]
    J0 = platform.body.inertia_matrix
    J1 = J0 + 0.041 * s**2 * np.diag([0, 1, 1])
    g_body = quat.rotate_inverse(q, [0, 0, -9.81])
    # M * (m1 s u1 / M) x g_body: the slider's own weight about the CR
    expected = np.cross([0.041 * s, 0, 0], g_body)
    assert_allclose(J1 @ w_dot1 - J0 @ w_dot0, expected, atol=1e-12)


def _energy(tb, x):
    J = tb.body.inertia_matrix
    q, w = x[:, 0:4], x[:, 4:7]
    kinetic = 0.5 * np.einsum("ni,ij,nj->n", w, J, w)
    # potential of the CM above the CR: m g (R r)_z
    potential = tb.body.mass * tb.gravity * quat.rotate(q, tb.body.cm_offset_vec)[:, 2]
    return kinetic + potential


def test_free_platform_conserves_energy_and_unit_norm(platform):
    m = build_model(platform)
    n, dt = 1200, platform.sensors.dt  # 60 s
    F = m.rollout(n, dt, substeps=8)
    x0 = m.x0(q=quat.qexp([0.05, -0.03, 0.2]), w=[0.3676, 0.1265, -1.4835])
    X = np.asarray(F(x0, np.zeros((m.nu, n)), m.p0)).T
    X = np.vstack([x0, X])
    E = _energy(platform, X)
    # the criterion of the foundation issue: 1e-8 relative over 60 s (RK4, h = dt/8)
    assert np.max(np.abs(E - E[0])) / abs(E[0]) < 1e-8
    assert np.max(np.abs(np.linalg.norm(X[:, 0:4], axis=1) - 1)) < 1e-12


def test_cmg_conserves_total_momentum(cmg):
    # yaw-only bearing, no external torque: J wz + h_z(delta) is constant (seed 001 eq. 10)
    m = build_model(cmg)
    n, dt = 1200, cmg.sensors.dt
    rng = np.random.default_rng(3)
    U = np.zeros((m.nu, n))
    U[0:4] = np.repeat(rng.uniform(-1, 1, (4, n // 20)), 20, axis=1)  # piecewise-constant rates
    x0 = m.x0(w=0.1)
    X = np.vstack([x0, np.asarray(m.rollout(n, dt)(x0, U, m.p0)).T])
    H = cmg_functions()["H"]
    hz = np.array([float(H(d, cmg.cmg.skew)[2]) for d in X[:, 2:6]]) * cmg.cmg.h0
    L = cmg.body.yaw_inertia * X[:, 1] + hz
    assert np.max(np.abs(L - L[0])) / np.max(np.abs(hz)) < 1e-8


def test_cmg_3dof_conserves_total_momentum_in_lab_frame(cmg):
    # 3-axis bearing, no gravity offset: R(q) (J w + h) is constant (seed 001 eqs. 10-11)
    J = np.array([[0.004, 0.0002, 0], [0.0002, 0.005, 0], [0, 0, 0.0035]])
    tb = cmg.replace(body=Body(dof=3, mass=0.76, inertia=tuple(map(tuple, J))))
    m = build_model(tb)
    n, dt = 400, tb.sensors.dt
    rng = np.random.default_rng(4)
    U = np.zeros((m.nu, n))
    U[0:4] = np.repeat(rng.uniform(-1, 1, (4, n // 20)), 20, axis=1)
    x0 = m.x0(w=[0.05, -0.02, 0.1])
    X = np.vstack([x0, np.asarray(m.rollout(n, dt, substeps=8)(x0, U, m.p0)).T])
    H = cmg_functions()["H"]
    h = np.array([np.asarray(H(d, tb.cmg.skew)).ravel() for d in X[:, 7:11]]) * tb.cmg.h0
    L_lab = quat.rotate(X[:, 0:4], X[:, 4:7] @ J.T + h)
    scale = np.max(np.linalg.norm(h, axis=1))
    assert np.max(np.abs(L_lab - L_lab[0])) / scale < 1e-7


@pytest.mark.parametrize("name", list(REGISTRY))
def test_every_effect_changes_the_model(name, platform, cmg):
    """Each registered effect, switched on, changes xdot or y at a generic state."""
    tb = cmg if name in ("spring_torque", "yaw_imbalance", "gimbal_deadzone") else platform
    if name.startswith("wheel_"):  # the wheel effects need reaction wheels
        tb = load_testbed("rw-3axis")
    value = {
        "cm_offset_error": (1e-4, -2e-4, 3e-4),
        "residual_dipole": (0.01, 0.02, 0.03),
        "yaw_imbalance": (0.1, -0.05),
    }.get(name, 0.1)
    base = build_model(tb)
    m = build_model(tb, {name: value})
    assert len(m.p_names) > len(base.p_names)
    if m.dof == 3:
        x = m.x0(q=quat.qexp([0.2, 0.1, 0.0]), w=[0.3, -0.2, 0.5])
    else:
        x = m.x0(yaw=0.3, w=0.5)
    u = np.zeros(m.nu)
    if tb.kind == "cmg":
        u[0:4] = 0.01
    else:
        u[m.index(["bx_lab", "by_lab", "bz_lab"], "u")] = [2e-4, 0, 6e-4]
    if tb.wheels is not None:  # spinning wheels under a torque command
        x[m.index(["W1", "W2", "W3", "W4"])] = [50.0, -30.0, 20.0, 10.0]
        u[m.index(["wc1", "wc2", "wc3", "wc4"], "u")] = [5e-4, -2e-4, 1e-4, 3e-4]
    nb = base.nx
    f0 = np.asarray(base.f(x[:nb], u, base.p0)).ravel()
    f1 = np.asarray(m.f(x, u, m.p0)).ravel()[:nb]
    y0 = np.asarray(base.h(x[:nb], u, base.p0)).ravel()
    y1 = np.asarray(m.h(x, u, m.p0)).ravel()
    if name == "sensor_lag":
        # the lag state starts at the true rate, so y is unchanged until w moves
        assert m.nx == nb + len(m.lag_index)
        return
    assert not (np.allclose(f0, f1, rtol=0, atol=1e-15) and np.allclose(y0, y1, rtol=0, atol=1e-15))


def test_effect_applicability_is_enforced(platform, cmg):
    assert "spring_torque" not in applicable_effects("platform", 3, True)
    assert "gimbal_deadzone" in applicable_effects("cmg", 1, False)
    with pytest.raises(InputError, match="spring_torque"):
        build_model(platform, {"spring_torque": 1e-4})
    with pytest.raises(InputError, match="unknown effect"):
        build_model(platform, {"magic_torque": 1.0})


def test_parameters_stay_symbolic(platform):
    """One Model evaluates for another inertia without being rebuilt."""
    m = build_model(platform)
    x = m.x0(w=[0.0, 0.0, 1.0])
    u = np.zeros(m.nu)
    a = np.asarray(m.f(x, u, m.p0)).ravel()
    b = np.asarray(m.f(x, u, m.params(J_zz=2 * platform.body.inertia_matrix[2, 2]))).ravel()
    assert not np.allclose(a, b)
    assert isinstance(m.f, ca.Function)


def test_sensor_lag_is_exact_for_a_ramp_and_transparent_at_zero(cmg):
    """First-order lag of a rate ramp: the exact solution, and tau = 0 reads the true rate."""
    m = build_model(cmg.replace(effects={}), {"sensor_lag": 0.2})
    n, dt = 40, cmg.sensors.dt
    torque = 1e-4  # N m about z: wz ramps at torque / J
    U = np.zeros((m.nu, n))
    U[m.index("tau_z", "u")[0]] = torque
    x0 = m.x0()
    X = np.asarray(m.rollout(n, dt)(x0, U, m.p0)).T
    t = dt * np.arange(1, n + 1)
    slope, tau = torque / cmg.body.yaw_inertia, 0.2
    # y' = (slope t - y)/tau, y(0) = 0  ->  y = slope (t - tau (1 - exp(-t/tau)))
    expected = slope * (t - tau * (1 - np.exp(-t / tau)))
    assert_allclose(X[:, m.lag_index[0]], expected, rtol=1e-9, atol=1e-15)
    m0 = build_model(cmg, {"sensor_lag": 0.0})
    X0 = np.asarray(m0.rollout(n, dt)(m0.x0(), U, m0.p0)).T
    assert_allclose(X0[:, m0.lag_index[0]], X0[:, 1], rtol=1e-12)


def test_residual_dipole_acts_on_a_cmg_in_a_cage(cmg):
    from airbearing.io.testbed import Field

    tb = cmg.replace(field=Field(lab=(2e-4, 0.0, 0.0)))
    m = build_model(tb, {"residual_dipole": (0.0, 0.05, 0.0)})
    xdot = np.asarray(m.f(m.x0(), np.zeros(m.nu), m.p0)).ravel()
    # tau_z = (m x b)_z = m_x b_y - m_y b_x = -0.05 * 2e-4
    assert_allclose(xdot[1] * tb.body.yaw_inertia, -0.05 * 2e-4, rtol=1e-12)


def test_step_with_dt_as_input_is_the_same_step(platform):
    """Model.step_dt(dt) and Model.step(dt) are the same arithmetic (RK4, lag, renormalised)."""
    m = build_model(platform, {"sensor_lag": 0.05, "aero_drag": 1e-4})
    x = m.x0(q=quat.qexp([0.2, 0.1, -0.3]), w=[0.3, -0.2, 0.5])
    u = np.zeros(m.nu)
    u[m.index(["s1", "bz_lab"], "u")] = [0.01, 6e-4]
    for dt in (0.05, 0.0731, 0.5):
        a = np.asarray(m.step(dt, 4)(x, u, m.p0)).ravel()
        b = np.asarray(m.step_dt(4)(x, u, m.p0, dt)).ravel()
        assert_allclose(b, a, rtol=0, atol=1e-15)  # rounding only


def test_structure_cache_one_model_per_structure():
    """Two testbeds differing only in values share one Model (equal as a cache key, so the
    compiled loops are reused) and each keeps its own values as p0; another structure
    (an effect added) is another Model."""
    import dataclasses

    from airbearing.models import structure_cache as sc

    tb = load_testbed("cmg-yaw")
    heavier = tb.replace(body=dataclasses.replace(tb.body, mass=tb.body.mass * 2))
    tag = ["test_structure_cache"]
    before = sc.structure_stats()
    a, b = sc.model_for(tb, tag), sc.model_for(heavier, tag)
    assert a == b and hash(a) == hash(b)
    assert a.p0[a.p_names.index("mass")] * 2 == b.p0[b.p_names.index("mass")]
    assert sc.structure_stats()["built"] - before["built"] == 1
    c = sc.model_for(tb.with_effects({"viscous_friction": 1e-6}), tag)
    assert c != a and "viscous_friction" in c.p_names
    assert sc.structure_stats()["built"] - before["built"] == 2
