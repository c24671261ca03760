"""The plant of a testbed's Model in CasADi: the state and input layout, the nominal physics
(attitude, gravity and field in body axes, the inertia about the CR, the sliders',
magnetorquers', CM offset's and disturbance torques) and ``f_plant(x, u, p) -> xdot``
(Euler's equations with the CMG momentum of seed 001 or the reaction wheels of
:mod:`airbearing.models.wheels`).
"""

from __future__ import annotations

import casadi as ca

from airbearing import quaternion as quat
from airbearing.io.testbed import Testbed
from airbearing.models.cmg import momentum_normalised
from airbearing.models.effects import EffectContext
from airbearing.models.parameters import INERTIA_NAMES, inertia_from_params
from airbearing.models.wheels import body_wheel_rates, motor_torque


def _state_input_names(kind: str, dof: int, n_wheels: int = 0) -> tuple[list[str], list[str]]:
    """The plant's state names and the input names (the layout of the module docstring)."""
    if dof == 3:
        x_names = ["qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    else:
        x_names = ["yaw", "wz"]
    if kind == "cmg":
        x_names += ["d1", "d2", "d3", "d4"]
        u_names = ["dd1", "dd2", "dd3", "dd4", "tau_x", "tau_y", "tau_z"]
    else:
        u_names = ["s1", "s2", "s3", "mx", "my", "mz", "bx_lab", "by_lab", "bz_lab"]
        u_names += ["tau_x", "tau_y", "tau_z"]
    x_names += [f"W{i}" for i in range(1, n_wheels + 1)]
    u_names += [f"wc{i}" for i in range(1, n_wheels + 1)]
    return x_names, u_names


def _nominal_physics(testbed: Testbed, has_field: bool, xp, X, U, P):
    """Attitude, gravity and field in body axes, the inertia about the CR and the torques of
    the nominal physics (sliders, magnetorquers, CM offset, disturbance input): the
    effects' context, the inertia and the attitude quaternion."""
    kind, dof = testbed.kind, testbed.body.dof
    tau_d = ca.vertcat(U["tau_x"], U["tau_y"], U["tau_z"])
    g_lab = ca.vertcat(0, 0, -P["gravity"])
    if dof == 3:
        q = xp[0:4]
        w = xp[4:7]
        g_body = quat.rotate_inverse(q, g_lab)
        yaw = None
    else:
        yaw = X["yaw"]
        w = ca.vertcat(X["wz"])
        q = quat.from_yaw(yaw)
        g_body = quat.rotate_inverse(q, g_lab)
    if dof == 3:
        J_cr = inertia_from_params(ca.vertcat(*[P[n] for n in INERTIA_NAMES]))
        r_cm = ca.vertcat(P["r_x"], P["r_y"], P["r_z"])
    else:
        J_cr = P["J_zz"]
        r_cm = ca.SX.zeros(3)
    torque = ca.SX.zeros(3)
    b_body = ca.SX.zeros(3)
    if kind == "platform" and testbed.masses is not None:
        axes = testbed.masses.axes_matrix
        s = ca.vertcat(U["s1"], U["s2"], U["s3"])
        for i in range(3):
            ui = ca.DM(axes[i])
            mi = P[f"m_{i + 1}"]
            # seed 004 eqs. 4-7: each slider moves the CM and adds a point-mass inertia
            r_cm = r_cm + mi * s[i] * ui / P["mass"]
            dJ = mi * s[i] ** 2 * (ca.DM.eye(3) - ca.mtimes(ui, ui.T))
            J_cr = J_cr + (dJ if dof == 3 else dJ[2, 2])
    if kind == "platform":  # the cage field is an input (a log may carry it)
        b_lab = ca.vertcat(U["bx_lab"], U["by_lab"], U["bz_lab"])
        b_body = quat.rotate_inverse(q, b_lab)
    elif testbed.field is not None:  # a CMG testbed inside a cage: the field is a constant
        b_body = quat.rotate_inverse(q, ca.DM(testbed.field.lab_vec))
    if kind == "platform" and testbed.magnetorquers is not None:
        m_dip = ca.vertcat(U["mx"], U["my"], U["mz"])
        torque = torque + ca.cross(m_dip, b_body)  # magnetorquer torque d x b (seed 000 eq. 2)
    # gravity torque of the CR -> CM offset (seed 004 eq. 11, seed 000 eq. 1)
    torque = torque + P["mass"] * ca.cross(r_cm, g_body) + tau_d
    if dof == 1:
        torque = torque[2]
    ctx = EffectContext(
        kind=kind,
        dof=dof,
        has_field=has_field,
        w=w,
        yaw=yaw,
        g_body=g_body,
        b_body=b_body,
        mass=P["mass"],
        torque=torque,
        gimbal_rates=ca.vertcat(*[U[f"dd{i}"] for i in range(1, 5)]) if kind == "cmg" else None,
        rate_measured=w,
    )
    if testbed.wheels is not None:
        n = testbed.wheels.n
        ctx.n_wheels = n
        ctx.wheel_speeds = ca.vertcat(*[X[f"W{i}"] for i in range(1, n + 1)])
        ctx.wheel_friction = ca.SX.zeros(n)
        ctx.wheel_gain = ca.SX.ones(n)
        ctx.wheel_inertia_scale = ca.SX.ones(n)
    return ctx, J_cr, q


def _plant(testbed: Testbed, ctx, J_eff, q, xp, X, U, u, p, P) -> ca.Function:
    """``f_plant(x, u, p) -> xdot``: Euler's equations with the CMG momentum (seed 001) or
    the reaction wheels (:mod:`airbearing.models.wheels`)."""
    kind, dof = testbed.kind, testbed.body.dof
    w = ctx.w
    if testbed.wheels is not None:
        return _plant_wheels(testbed, ctx, J_eff, q, xp, u, p, P, U)
    if kind == "cmg":
        delta = ca.vertcat(*[X[f"d{i}"] for i in range(1, 5)])
        dd = ctx.gimbal_rates
        A = ca.jacobian(momentum_normalised(delta, P["beta"]), delta)
        h_dot = P["h0"] * ca.mtimes(A, dd)  # seed 001 eq. 14
        h = P["h0"] * momentum_normalised(delta, P["beta"])
    if dof == 3:
        rhs = ctx.torque - ca.cross(w, ca.mtimes(J_eff, w))  # seed 004 eq. 11
        if kind == "cmg":
            rhs = rhs - h_dot - ca.cross(w, h)  # seed 001 eq. 10
        w_dot = ca.solve(J_eff, rhs)
        x_dot = [quat.qdot(q, w), w_dot]
    else:
        rhs = ctx.torque
        if kind == "cmg":
            rhs = rhs - h_dot[2]  # seed 001 eq. 10, yaw row (w x h has no z part for w = wz z)
        x_dot = [w, rhs / J_eff]
    if kind == "cmg":
        x_dot.append(dd)
    return ca.Function("f_plant", [xp, u, p], [ca.vertcat(*x_dot)], ["x", "u", "p"], ["xdot"])


def _plant_wheels(testbed: Testbed, ctx, J_locked, q, xp, u, p, P, U) -> ca.Function:
    """``f_plant`` of a platform with reaction wheels: eqs. (3)-(4) of models/wheels.py."""
    wh = testbed.wheels
    n = wh.n
    Iw = ctx.wheel_inertia_scale * ca.vertcat(*[P[f"Iw_{i}"] for i in range(1, n + 1)])
    W = ctx.wheel_speeds
    command = ca.vertcat(*[U[f"wc{i}"] for i in range(1, n + 1)])
    tau_m = motor_torque(
        command,
        W,
        Iw,
        ctx.wheel_gain,
        mode=wh.command,
        max_torque=wh.max_torque,
        max_speed=wh.max_speed,
        speed_loop_tau=wh.speed_loop_tau,
    )
    g = tau_m - ctx.wheel_friction
    w_dot, W_dot = body_wheel_rates(
        J_locked, ctx.w, ctx.torque, W, Iw, wh.axes_matrix, g, testbed.body.dof
    )
    if testbed.body.dof == 3:
        x_dot = [quat.qdot(q, ctx.w), w_dot, W_dot]
    else:
        x_dot = [ctx.w, w_dot, W_dot]
    return ca.Function("f_plant", [xp, u, p], [ca.vertcat(*x_dot)], ["x", "u", "p"], ["xdot"])
