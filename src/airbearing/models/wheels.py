"""Reaction wheels in the Model: motor torque, limits and the coupled body-wheel dynamics.

FORMATS.md, "Frames and conventions": wheel ``i`` spins about the unit vector ``a_i``
(body axes) at the speed ``W_i`` relative to the body, with spin-axis inertia ``Iw_i``;
``J`` (``body.inertia``) is the inertia of everything that rotates, the wheels included
as if locked.

Equations
---------
Total angular momentum (body axes) and its balance with the external torques ``tau``
(gravity, the cage, the disturbance input, the body effects)::

    H = J w + sum_i Iw_i W_i a_i,          dH/dt + w x H = tau                      (1)

and each wheel's own axis::

    Iw_i (a_i . dw/dt + dW_i/dt) = tau_m_i - tau_f_i =: g_i                          (2)

with ``tau_m_i`` the motor torque and ``tau_f_i`` the friction of the wheel's bearing.
``dH/dt`` in (1) is the derivative of the body-axes components (the wheels are fixed in
the body, ``a_i`` constant), ``J dw/dt + sum_i Iw_i (dW_i/dt) a_i``. From (2),
``Iw_i dW_i/dt = g_i - Iw_i a_i a_i^T dw/dt``; put into (1)::

    (J - sum_i Iw_i a_i a_i^T) dw/dt = tau - w x H - sum_i g_i a_i                  (3)
    dW_i/dt = g_i / Iw_i - a_i . dw/dt                                               (4)

``J_eff = J - sum_i Iw_i a_i a_i^T`` is the inertia of the body with each wheel free to
spin (the locked inertia less each wheel's spin-axis part): positive definite for any
real build, since the wheel's own spin inertia is part of ``J``. Only the reaction
``-sum g_i a_i`` of the wheels' net torques, and the gyroscopic ``w x H`` of their
momentum, act on the body.

dof = 1 (every ``a_i = s_i z``, ``s_i = +-1``; ``w = wz z`` and ``H`` along z, so
``w x H = 0``)::

    (J_zz - sum_i Iw_i) dwz/dt = tau_z - sum_i s_i g_i,   dW_i/dt = g_i / Iw_i - s_i dwz/dt

Example (the oracle of tests/wheels): one wheel, free body, only viscous friction
``g = -c W``: ``dW/dt = -c W (1/Iw + 1/(J_zz - Iw))``, an exponential decay at the rate
``c J_zz / (Iw (J_zz - Iw))`` while ``J_zz wz + Iw W`` stays constant.

Motor torque
------------
``command = "torque"``: the logged command ``u_i`` (held over the sample) is the torque
the driver asks for; ``command = "speed"``: the driver's speed loop asks for
``Iw_i (u_i - W_i) / speed_loop_tau``. Either request is clipped to
``+-max_torque`` (a saturation is part of the physics), then the motor gives
``(1 + wheel_torque_error_i)`` times it. Near the speed limit the torque that would
speed the wheel up further (same sign as ``W_i``) fades linearly to zero over the last
:data:`SPEED_LIMIT_BAND` of ``max_speed`` (full torque below
``(1 - SPEED_LIMIT_BAND) max_speed``, none at ``max_speed`` and beyond); a torque that
slows the wheel is never cut. The factor is continuous in ``W_i`` and in the command, so
the fixed-step integrator sees no jump.
"""

from __future__ import annotations

import casadi as ca

__all__ = ["SPEED_LIMIT_BAND", "body_wheel_rates", "motor_torque"]

#: Fraction of ``max_speed`` over which a speeding-up motor torque fades to zero.
SPEED_LIMIT_BAND = 0.01


def motor_torque(command, W, Iw, gain, *, mode: str, max_torque: float, max_speed: float,
                 speed_loop_tau: float | None):  # fmt: skip
    """Motor torques of the wheels (N m), shape (n,), from the held commands.

    Parameters
    ----------
    command : casadi.SX, shape (n,)
        Logged commands ``wc_i``: N m (``mode = "torque"``) or rad/s (``"speed"``).
    W : casadi.SX, shape (n,)
        Wheel speeds relative to the body, rad/s.
    Iw : casadi.SX, shape (n,)
        Wheel inertias, kg m^2 (used by the speed loop).
    gain : casadi.SX or float, shape (n,)
        ``1 + wheel_torque_error`` per wheel.
    mode : {"torque", "speed"}
    max_torque : float
        N m, clip of the requested torque.
    max_speed : float
        rad/s, the motor adds no speed beyond it (see the module docstring).
    speed_loop_tau : float or None
        s, time constant of the driver's speed loop (``mode = "speed"``).
    """
    if mode == "speed":
        request = Iw * (command - W) / speed_loop_tau
    else:
        request = command
    tau = gain * ca.fmin(ca.fmax(request, -max_torque), max_torque)
    band = SPEED_LIMIT_BAND * max_speed
    fade = ca.fmin(ca.fmax((max_speed - ca.fabs(W)) / band, 0.0), 1.0)
    speeding_up = tau * W > 0
    return ca.if_else(speeding_up, fade * tau, tau)


def body_wheel_rates(J, w, tau, W, Iw, axes, g, dof: int):
    """``(dw/dt, dW/dt)`` of eqs. (3)-(4) of the module docstring.

    Parameters
    ----------
    J : casadi.SX
        Locked inertia about the CR, kg m^2: (3, 3) for dof 3, scalar ``J_zz`` for dof 1.
    w : casadi.SX
        Body rate, rad/s: (3,) for dof 3, (1,) for dof 1.
    tau : casadi.SX
        External torque, N m, same shape as ``w``.
    W, Iw, g : casadi.SX, shape (n,)
        Wheel speeds (rad/s), inertias (kg m^2), net wheel torques ``tau_m - tau_f`` (N m).
    axes : numpy.ndarray, shape (n, 3)
        Spin-axis unit vectors (body axes); dof 1: ``(0, 0, +-1)`` rows.
    dof : {1, 3}
    """
    n = axes.shape[0]
    if dof == 3:
        A = ca.DM(axes)  # n x 3, one wheel per row
        h_w = ca.mtimes(A.T, Iw * W)
        J_eff = J - ca.mtimes(A.T, ca.mtimes(ca.diag(Iw), A))
        rhs = tau - ca.cross(w, ca.mtimes(J, w) + h_w) - ca.mtimes(A.T, g)
        w_dot = ca.solve(J_eff, rhs)
        W_dot = g / Iw - ca.mtimes(A, w_dot)
    else:
        s = ca.DM([float(axes[i][2]) for i in range(n)])  # +-1
        J_eff = J - ca.sum1(Iw)
        w_dot = (tau - ca.dot(s, g)) / J_eff
        W_dot = g / Iw - s * w_dot
    return w_dot, W_dot
