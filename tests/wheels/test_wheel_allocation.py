"""Reaction-wheel allocation: the pseudo-inverse, the null space and the torque limit.

References are the physics of FORMATS.md (torque on the body ``-sum tau_m_i a_i``) and
linear algebra: no numbers from a run.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from airbearing.design.wheels import allocation, bias_speeds, dump_dipole, saturate_torques
from airbearing.errors import InputError

_S = np.sqrt(0.5)
#: wheel sets: (axes, dof); a 4-wheel pyramid (skew 45 deg), an orthogonal triad, a
#: triad plus a skewed fourth wheel, one yaw wheel, two opposed yaw wheels
SETS = {
    "pyramid": ([[_S, 0, _S], [0, _S, _S], [-_S, 0, _S], [0, -_S, _S]], 3),
    "triad": ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], 3),
    "triad+skew": ([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1 / 3**0.5] * 3], 3),
    "yaw": ([[0, 0, 1]], 1),
    "yaw pair": ([[0, 0, 1], [0, 0, -1]], 1),
}
#: exact up to rounding: the pseudo-inverse of a well-conditioned 3 x n matrix
TOL = 1e-12


@pytest.mark.parametrize("name", SETS)
def test_allocation_reproduces_the_commanded_torque(name):
    axes, dof = SETS[name]
    A = np.asarray(axes, float)
    M, _ = allocation(A, dof)
    free = [2] if dof == 1 else [0, 1, 2]
    rng = np.random.default_rng(1)
    for T in rng.normal(size=(5, 3)) * 1e-3:
        tau = M @ T
        body = -A.T @ tau  # FORMATS.md: the torque on the body is -sum tau_m_i a_i
        assert np.allclose(body[free], T[free], rtol=0, atol=TOL * 1e-3)


@pytest.mark.parametrize("name", SETS)
def test_null_space_exchanges_no_torque(name):
    axes, dof = SETS[name]
    A = np.asarray(axes, float)
    _, N = allocation(A, dof)
    free = [2] if dof == 1 else [0, 1, 2]
    assert np.allclose(A[:, free].T @ N, 0, atol=TOL)
    assert np.allclose(N @ N, N, atol=TOL)  # a projector
    # the null space has the dimension of the redundancy
    assert np.linalg.matrix_rank(N, tol=1e-9) == A.shape[0] - len(free)
    b = bias_speeds(A, dof, 100.0)
    assert np.allclose(A[:, free].T @ b, 0, atol=1e-9)  # the bias stores no momentum
    if A.shape[0] > len(free):
        assert np.isclose(np.abs(b).max(), 100.0)


def test_pyramid_bias_spins_every_wheel_at_the_same_speed():
    # the pyramid's null direction is (1, -1, 1, -1): A^T v = (c (v1 - v3), c (v2 - v4),
    # s (v1 + v2 + v3 + v4)) = 0
    b = bias_speeds(SETS["pyramid"][0], 3, 50.0)
    assert np.allclose(b, [50, -50, 50, -50])


def test_axes_that_miss_a_free_axis_are_refused():
    with pytest.raises(InputError, match="cannot make torque about every free axis"):
        allocation([[1, 0, 0], [0, 1, 0]], 3)


def test_scaling_keeps_the_direction_and_clipping_does_not():
    tau = ca.DM([3e-3, -1e-3, 0.5e-3])
    scaled = np.asarray(saturate_torques(tau, 2e-3, "scale")).ravel()
    clipped = np.asarray(saturate_torques(tau, 2e-3, "clip")).ravel()
    assert np.isclose(np.abs(scaled).max(), 2e-3)
    t = np.asarray(tau).ravel()
    assert np.allclose(scaled, t * (2e-3 / 3e-3), rtol=1e-12)  # one factor on every wheel
    assert np.allclose(clipped, [2e-3, -1e-3, 0.5e-3])
    within = np.asarray(saturate_torques(ca.DM([1e-3, -1e-3]), 2e-3, "scale")).ravel()
    assert np.allclose(within, [1e-3, -1e-3])  # unsaturated: untouched


def test_dumping_torque_removes_the_momentum_across_the_field():
    h = np.array([1e-3, -2e-3, 0.5e-3])  # N m s
    b = np.array([2e-5, 0.0, -4e-5])  # T
    m = np.asarray(dump_dipole(ca.DM(h), ca.DM(b), 0.1, 10.0)).ravel()
    torque = np.cross(m, b)  # the magnetorquer torque m x b (seed 000 eq. 2)
    h_perp = h - b * (h @ b) / (b @ b)
    assert np.allclose(torque, -0.1 * h_perp, rtol=1e-12, atol=0)
    # the dipole limit scales, keeping the direction
    small = np.asarray(dump_dipole(ca.DM(h), ca.DM(b), 0.1, 1.0)).ravel()
    assert np.isclose(np.abs(small).max(), 1.0) and np.allclose(small / small[0], m / m[0])
