"""Linearisation: trim points, exact CasADi Jacobians, discretisation."""

import numpy as np
import pytest

from airbearing import quaternion as quat
from airbearing.design.linearise import (
    delay_system,
    discretise,
    linearisation,
    linearise,
    lowpass_system,
    scaled_params,
    trim,
)
from airbearing.io.testbed import load_testbed
from airbearing.models.model import build_model


@pytest.fixture(scope="module")
def platform():
    return build_model(load_testbed("platform-3dof"))


@pytest.fixture(scope="module")
def cmg():
    return build_model(load_testbed("cmg-yaw"))


def test_trim_sliders_cancel_in_plane_offset(platform):
    tb = platform.testbed
    tp = trim(platform)
    s = tp.u[platform.index(["s1", "s2", "s3"], "u")]
    # seed 004 eqs. 4-5: the sliders cancel the in-plane CM offset, m_i s_i = -mass r_i
    want = -tb.body.mass * tb.body.cm_offset_vec[:2] / tb.masses.mass_vec[:2]
    np.testing.assert_allclose(s[:2], want, rtol=1e-8)  # IPOPT tol 1e-14 on a linear problem
    assert abs(s[2]) < 1e-9  # the z slider does not change a level platform's torque
    assert tp.residual < 1e-12
    # 61 mm and 108 mm are past the 37 mm travel of platform-3dof: reported, not hidden
    assert len(tp.limit_violations) == 2


def test_platform_is_the_hand_derived_pendulum(platform):
    """About the balanced point: torque = mass g r_z per radian of tilt (each level axis)."""
    tb = platform.testbed
    tp = trim(platform)
    sys = linearise(platform, tp)
    assert list(sys.state_labels) == ["th_x", "th_y", "th_z", "wx", "wy", "wz"]
    s = tp.u[platform.index(["s1", "s2", "s3"], "u")]
    J = tb.body.inertia_matrix.copy()
    for i, u in enumerate(tb.masses.axes_matrix):  # seed 004 eqs. 6-7: slider point masses
        J += tb.masses.mass_vec[i] * s[i] ** 2 * (np.eye(3) - np.outer(u, u))
    mgr = tb.body.mass * tb.gravity * tb.body.cm_offset_vec[2]
    want = np.linalg.solve(J, np.diag([mgr, mgr, 0.0]))
    A = np.asarray(sys.A)
    np.testing.assert_allclose(A[3:6, 0:3], want, rtol=1e-9, atol=1e-12)  # exact algebra
    np.testing.assert_allclose(A[0:3, 3:6], np.eye(3), atol=1e-12)  # theta_dot = w at trim
    # slider torque m_i u_i x g_body (g_body = [0, 0, -g]): s1 -> +m g about y, s2 -> -m g about x
    B = np.asarray(sys.B)
    m1, m2, g = tb.masses.mass_vec[0], tb.masses.mass_vec[1], tb.gravity
    iu = list(sys.input_labels)
    np.testing.assert_allclose(J @ B[3:6, iu.index("s1")], [0, m1 * g, 0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(J @ B[3:6, iu.index("s2")], [-m2 * g, 0, 0], rtol=1e-9, atol=1e-12)
    # magnetorquer torque d x b with b = [0, 0, b]: mx -> -b about y, my -> +b about x
    b = tb.field.lab_vec[2]
    np.testing.assert_allclose(J @ B[3:6, iu.index("mx")], [0, -b, 0], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(J @ B[3:6, iu.index("my")], [b, 0, 0], rtol=1e-9, atol=1e-15)


def _reduced_f(model, tp, xi, u):
    """Nonlinear dynamics in the same minimal coordinates, NumPy, for finite differences."""
    x = np.array(tp.x, dtype=float)
    if model.dof == 3:
        th = xi[:3]
        dq = np.concatenate([[np.sqrt(1 - th @ th / 4)], th / 2])
        x[:4] = quat.qmul(tp.x[:4], dq)
        x[4:] = tp.x[4:] + xi[3:]
    else:
        x = x + xi
    f = np.asarray(model.f(x, u, tp.p)).ravel()
    y = np.asarray(model.h(x, u, tp.p)).ravel()
    if model.dof == 3:
        qd = quat.qmul(quat.qconj(tp.x[:4]), f[:4])
        f = np.concatenate([2 * qd[1:4], f[4:]])
    return f, y


@pytest.mark.parametrize("which", ["platform", "cmg"])
def test_jacobians_agree_with_finite_differences(which, platform, cmg):
    model = platform if which == "platform" else cmg
    tp = trim(model, gimbals=[0.3, -0.2, 0.5, 0.1]) if which == "cmg" else trim(model)
    A, B, C, D = linearisation(model).matrices(tp)
    n = A.shape[0]
    h = 1e-6
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        fp, yp = _reduced_f(model, tp, e, tp.u)
        fm, ym = _reduced_f(model, tp, -e, tp.u)
        # central differences: truncation O(h^2 f''') ~ 1e-12, rounding ~ 1e-16 / h = 1e-10
        np.testing.assert_allclose(A[:, j], (fp - fm) / (2 * h), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(C[:, j], (yp - ym) / (2 * h), rtol=1e-5, atol=1e-7)
    for j in range(model.nu):
        e = np.zeros(model.nu)
        e[j] = 1e-6 if model.u_names[j] not in ("bx_lab", "by_lab", "bz_lab") else 1e-9
        fp, _ = _reduced_f(model, tp, np.zeros(n), tp.u + e)
        fm, _ = _reduced_f(model, tp, np.zeros(n), tp.u - e)
        np.testing.assert_allclose(B[:, j], (fp - fm) / (2 * e[j]), rtol=1e-5, atol=1e-6)


def test_parameters_stay_symbolic(cmg):
    """Re-evaluating with 15 % more inertia equals a model rebuilt from a changed testbed."""
    tp = trim(cmg)
    lin = linearisation(cmg)
    p = scaled_params(cmg, inertia_scale=1.15)
    A1, B1, _, _ = lin.matrices(tp, p)
    assert linearisation(cmg) is lin  # built once, cached
    tb = cmg.testbed
    body = type(tb.body)(dof=1, mass=tb.body.mass, inertia=1.15 * tb.body.yaw_inertia)
    other = build_model(tb.replace(body=body))
    A2, B2, _, _ = linearisation(other).matrices(trim(other))
    np.testing.assert_allclose(B1, B2, rtol=1e-12)  # same algebra, rounding only
    # seed 001 eq. 10, yaw row: J w' = -h0 A_z dd, A_z = sin(beta) cos(delta_i) (eq. 15)
    want = -tb.cmg.h0 * np.sin(tb.cmg.skew) / (1.15 * tb.body.yaw_inertia)
    np.testing.assert_allclose(B1[1, :4], want, rtol=1e-12)


def test_discretise_zoh_delay_and_lowpass(cmg):
    T = cmg.testbed.sensors.dt
    sys = linearise(cmg)[["yaw", "wz"], ["dd1", "tau_z"]]
    d0 = discretise(sys, T, delay_samples=0)
    # ZOH of a double integrator: x+ = [[1, T], [0, 1]] x + [T^2/2, T] b u (exact)
    b = np.asarray(sys.B)[1, 1]
    np.testing.assert_allclose(np.asarray(d0.B)[:2, 1], [b * T**2 / 2, b * T], rtol=1e-12)
    d1 = discretise(sys, T, delay_samples=1)
    assert d1.nstates == d0.nstates + 1  # one delayed actuator input, the torque is not delayed
    # one sample of delay: the response to dd1 starts one sample later
    w = np.array([0.1, 1.0])
    ratio = d1[1, "dd1"].frequency_response(w).complex / d0[1, "dd1"].frequency_response(w).complex
    np.testing.assert_allclose(ratio.ravel(), np.exp(-1j * w * T), rtol=1e-9)
    lp = lowpass_system(["wz"], T, 0.25)
    # seed 001 eq. 3: unit DC gain, pole at 1 - f_g
    np.testing.assert_allclose(lp.dcgain(), 1.0, rtol=1e-12)
    np.testing.assert_allclose(lp.poles(), [0.75], rtol=1e-12)
    dl = discretise(sys, T, delay_samples=1, lowpass=0.25, lowpass_outputs=("wz",))
    assert dl.nstates == d1.nstates + 1 and "wz" in dl.output_labels
    assert delay_system(["a", "b"], T, 2).nstates == 4
