"""The balancing laws' torque algebra, CasADi expressions that also take and give NumPy
arrays: the sliders' matrix and torque (seed 000 eq. 2, seed 004 eqs. 4-5, 12-13), the
slider displacements and the dipole that make a torque (seed 000 eqs. 5, 7), the three
terms of the seed-000 PID (eq. 3) and the cage field in body axes.

Sign conventions: see :mod:`airbearing.design.balancing`.
"""

from __future__ import annotations

from functools import wraps

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.errors import InputError

__all__ = [
    "Z_HAT",
    "dipole_for_torque",
    "field_in_body",
    "in_plane_pid",
    "perp",
    "slider_matrix",
    "slider_torque",
    "torque_to_sliders",
]

#: The body's z axis, up when level: the seed-000 error is ``g_hat x z_hat``.
Z_HAT = ca.DM([0.0, 0.0, 1.0])


def _numeric(fn):
    """Let a CasADi expression builder also take and return NumPy arrays."""

    @wraps(fn)
    def wrapper(*args, **kwargs):
        if any(isinstance(a, ca.SX | ca.MX) for a in args):
            return fn(*args, **kwargs)
        out = fn(*[ca.DM(np.asarray(a, float)) if _is_array(a) else a for a in args], **kwargs)
        if isinstance(out, tuple):
            return tuple(np.asarray(o, float).ravel() for o in out)
        return np.asarray(out, float).ravel()

    return wrapper


def _is_array(a) -> bool:
    return isinstance(a, np.ndarray | list | tuple | ca.DM | float | int)


def perp(v, g_hat):
    """Component of ``v`` orthogonal to the unit ``g_hat`` (seed 004 eq. 25)."""
    return v - ca.dot(v, g_hat) * g_hat


def slider_matrix(axes, masses) -> np.ndarray:
    """``T`` with ``s = T M``: slider positions (m) giving the mass moment ``M`` (kg m).

    The sliders move the mass moment by ``M = sum_i m_i s_i u_i = A^T diag(m) s`` (seed 004
    eqs. 4-5; FORMATS.md), so ``T = (A^T diag(m))^-1`` with ``A`` the rail unit vectors as
    rows. Rails along any three independent axes work (seed 004 mounts them rotated 45 deg
    about z).
    """
    A = np.asarray(axes, dtype=float)
    m = np.asarray(masses, dtype=float).reshape(-1)
    if A.shape != (3, 3) or m.shape != (3,):
        raise InputError(f"slider axes {A.shape} and masses {m.shape}: expected (3, 3) and (3,)")
    if np.any(m <= 0):
        raise InputError(f"masses.mass {m.tolist()}: every sliding mass must be > 0 kg")
    B = A.T * m
    if abs(np.linalg.det(B)) < 1e-9 * np.prod(m):
        raise InputError(f"masses.axes {A.tolist()}: the three rails must span 3-D space")
    return np.linalg.inv(B)


@_numeric
def torque_to_sliders(tau, g_hat, gravity, axes, masses):
    """Slider displacements (m) that make the torque ``tau`` (N m, body) about the CR.

    ``M = g_hat x tau / |g|`` (seed 000 eq. 5, seed 004 eq. 13, written for the mass
    moment ``M`` instead of one combined mass), then ``s = T M`` (:func:`slider_matrix`).
    Exact for the part of ``tau`` orthogonal to gravity; gravity cannot make the rest.

    Parameters
    ----------
    tau : (3,) N m, body axes.
    g_hat : (3,) unit gravity direction, body axes.
    gravity : float, m/s^2.
    axes : (3, 3) rail unit vectors (rows); masses : (3,) kg.
    """
    M = ca.cross(g_hat, tau) / gravity  # seed 000 eq. 5, seed 004 eq. 13
    return ca.mtimes(ca.DM(slider_matrix(np.asarray(axes), np.asarray(masses))), M)


@_numeric
def slider_torque(s, g_body, axes, masses):
    """Torque (N m) of slider displacements ``s`` (m) in gravity ``g_body`` (m/s^2, body).

    ``sum_i m_i s_i u_i x g`` (seed 000 eq. 2, seed 004 eq. 12).
    """
    A = ca.DM(np.asarray(axes, dtype=float))
    m = ca.DM(np.asarray(masses, dtype=float).reshape(-1))
    M = ca.mtimes(A.T, m * s)
    return ca.cross(M, g_body)


@_numeric
def dipole_for_torque(tau, b_body):
    """Dipole (A m^2) whose torque ``d x b`` is ``tau`` (N m) less its part along ``b``.

    ``d = b_hat x tau / |b|`` (seed 000 eq. 7).
    """
    return ca.cross(b_body, tau) / ca.sumsqr(b_body)


@_numeric
def in_plane_pid(g_hat, w, integral, gains):
    """The three terms of the seed-000 PID (eq. 3), each in N m.

    Parameters
    ----------
    g_hat : (3,) unit gravity direction, body. w : (3,) rate, rad/s.
    integral : (3,) ``int g_hat x z_hat dt`` (s), body. gains : ``K_p, K_d, K_d K_i``.

    Returns
    -------
    tau_p, tau_i, tau_d : the proportional, integral and derivative torques.
    """
    e = ca.cross(g_hat, Z_HAT)  # seed 000 eq. 3: error g_hat x z_hat
    tau_p = gains[0] * e
    tau_i = gains[2] * perp(integral, g_hat)
    tau_d = -gains[1] * perp(w, g_hat)
    return tau_p, tau_i, tau_d


def field_in_body(field_lab, g_hat, q):
    """Cage field in body axes (T) as the controller knows it.

    A vertical field (seed 000: anti-parallel to gravity) needs only the accelerometer:
    ``b = -b_z g_hat``. Any other field is rotated with the measured attitude ``q``.
    """
    b = np.asarray(field_lab, dtype=float)
    if np.hypot(b[0], b[1]) <= 1e-12 * abs(b[2]):
        return -b[2] * g_hat

    return quat.rotate_inverse(q, ca.DM(b))
