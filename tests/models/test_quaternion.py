"""Quaternion algebra: group properties (hypothesis) and agreement between CasADi and NumPy."""

import casadi as ca
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from airbearing import quaternion as quat

finite = st.floats(-1.0, 1.0, allow_nan=False)
vec3 = st.tuples(finite, finite, finite).map(np.array)
nonzero3 = vec3.filter(lambda v: np.linalg.norm(v) > 0.1)
unit_q = (
    st.tuples(finite, finite, finite, finite)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
    .map(lambda v: np.array(v) / np.linalg.norm(v))
)


@given(unit_q, unit_q, unit_q)
def test_product_is_associative(a, b, c):
    assert_allclose(quat.qmul(quat.qmul(a, b), c), quat.qmul(a, quat.qmul(b, c)), atol=1e-12)


@given(unit_q)
def test_conjugate_is_inverse(q):
    assert_allclose(quat.qmul(q, quat.qconj(q)), [1, 0, 0, 0], atol=1e-12)


@given(unit_q, unit_q)
def test_rotation_matrix_is_a_homomorphism(a, b):
    # R(a (x) b) = R(a) R(b): the Hamilton product composes body -> lab rotations
    assert_allclose(
        quat.rotation_matrix(quat.qmul(a, b)),
        quat.rotation_matrix(a) @ quat.rotation_matrix(b),
        atol=1e-12,
    )


@given(unit_q, vec3)
def test_rotate_and_inverse(q, v):
    R = quat.rotation_matrix(q)
    assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert_allclose(quat.rotate_inverse(q, quat.rotate(q, v)), v, atol=1e-12)


@given(nonzero3, nonzero3)
def test_between_takes_a_to_b_by_the_shortest_arc(a, b):
    ua, ub = a / np.linalg.norm(a), b / np.linalg.norm(b)
    if ua @ ub < -0.999:
        return  # opposite directions: no unique shortest arc
    q = quat.between(a, b)
    assert_allclose(quat.rotate(q, ua), ub, atol=1e-9)
    # shortest arc: the rotation angle is the angle between the two directions
    angle = 2 * np.arctan2(np.linalg.norm(q[1:]), q[0])
    assert_allclose(angle, np.arccos(np.clip(ua @ ub, -1, 1)), atol=1e-7)


@given(vec3)
def test_exp_is_unit_and_matches_axis_angle(v):
    q = quat.qexp(v)
    assert_allclose(np.linalg.norm(q), 1.0, atol=1e-14)
    angle = np.linalg.norm(v)
    if angle > 1e-6:
        assert_allclose(q, quat.from_axis_angle(v / angle, angle), atol=1e-12)


@settings(max_examples=25)
@given(unit_q, vec3)
def test_casadi_and_numpy_agree(q, w):
    qs, ws = ca.SX.sym("q", 4), ca.SX.sym("w", 3)
    f = ca.Function("f", [qs, ws], [quat.qdot(qs, ws), quat.rotate(qs, ws), quat.qexp(ws)])
    qd, rv, ex = (np.asarray(o).ravel() for o in f(q, w))
    assert_allclose(qd, quat.qdot(q, w), atol=1e-14)
    assert_allclose(rv, quat.rotate(q, w), atol=1e-14)
    assert_allclose(ex, quat.qexp(w), atol=1e-14)


def test_qdot_matches_seed004_eq1():
    # seed 004 eq. 1 writes the kinematics scalar-last: d[q1..q4]/dt = 1/2 Omega(w) [q1..q4]
    rng = np.random.default_rng(0)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    wx, wy, wz = rng.normal(size=3)
    omega = np.array([[0, wz, -wy, wx], [-wz, 0, wx, wy], [wy, -wx, 0, wz], [-wx, -wy, -wz, 0]])
    q_last = np.r_[q[1:], q[0]]
    expected = 0.5 * omega @ q_last
    got = quat.qdot(q, [wx, wy, wz])
    assert_allclose(np.r_[got[1:], got[0]], expected, atol=1e-14)


def test_yaw_and_stacked_inputs():
    yaws = np.linspace(-3, 3, 7)
    q = quat.from_yaw(yaws)
    assert q.shape == (7, 4)
    assert_allclose(quat.yaw_of(q), yaws, atol=1e-12)
    assert_allclose(quat.tilt_of(q), 0, atol=1e-7)


def test_exp_has_finite_second_derivatives_at_zero():
    # IPOPT needs the Hessian of qexp at the origin; if_else must not leak a NaN branch
    v = ca.SX.sym("v", 3)
    q = quat.qexp(v)
    H = ca.Function("H", [v], [ca.hessian(q[0], v)[0], ca.jacobian(q, v)])
    hess, jac = (np.asarray(o) for o in H(np.zeros(3)))
    assert np.all(np.isfinite(hess)) and np.all(np.isfinite(jac))
    assert_allclose(hess, -0.25 * np.eye(3), atol=1e-15)  # cos(t/2) = 1 - t^2/8 + ...
    assert_allclose(jac[1:], 0.5 * np.eye(3), atol=1e-15)


def test_continuous_branch_removes_sign_jumps():
    q = quat.from_yaw(np.linspace(0, 6, 50))
    flipped = q * np.where(np.arange(50) % 7 == 3, -1.0, 1.0)[:, None]
    assert_allclose(quat.continuous_branch(flipped), q, atol=1e-15)


def test_one_sign_continuity_routine_one_and_three_lags():
    """continuous_branch is continuous_signs with one lag; three lags keep the segment's
    branch across one glitched sample that one lag follows (q and -q are one attitude)."""
    from airbearing.quaternion import continuous_signs

    rng = np.random.default_rng(3)
    q = quat.normalize(np.cumsum(rng.normal(scale=0.02, size=(50, 4)), axis=0) + [1, 0, 0, 0])
    signs = np.where(rng.random(50) < 0.3, -1.0, 1.0)
    signs[0] = 1.0
    assert_allclose(continuous_signs(q * signs[:, None], lags=1), q, atol=1e-15)
    assert_allclose(quat.continuous_branch(q * signs[:, None]), q, atol=1e-15)
    glitched = q.copy()
    d = q[19] - q[21]  # a wrong sample at row 20, agreeing with row 19 and not with 21
    glitched[20] = d / np.linalg.norm(d)
    assert glitched[20] @ q[19] > 0 > glitched[20] @ q[21]
    assert_allclose(continuous_signs(glitched, lags=3)[21:], q[21:], atol=1e-15)
    assert_allclose(continuous_signs(glitched, lags=1)[21:], -q[21:], atol=1e-15)


def test_log_inverts_exp_the_shortest_way():
    """qlog(qexp(v)) = v for |v| < pi (the shortest rotation), for q and -q alike, and the
    identity maps to zero (rounding tolerance)."""
    rng = np.random.default_rng(0)
    axis = rng.normal(size=(50, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    v = axis * rng.uniform(0.0, np.pi - 1e-3, size=(50, 1))
    q = quat.qexp(v)
    assert_allclose(quat.qlog(q), v, atol=1e-12)
    assert_allclose(quat.qlog(-q), v, atol=1e-12)
    assert_allclose(quat.qlog(np.array([1.0, 0, 0, 0])), np.zeros(3), atol=0)
