"""The stability report's responses: the reference scenario in the linear discrete model
and in the nonlinear CasADi closed loop (same controller, ideal actuators, the delay)
overlaid, and the attitude loop's response to a disturbance torque step.
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.simulation.simulate import closed_loop_rollout
from airbearing.design.loops import Loop, with_delay
from airbearing.design.tuning import scenario_response
from airbearing.design.tuning.responses import held_input_response
from airbearing.reporting.html import Report
from airbearing.reporting.stability_words import words

_DIST_TORQUE = 7e-5  # N m, seed 000 Tables 1-2: residual torque after balancing (~7e-5 N m)


def nonlinear_scenario(loop: Loop, t_end: float):
    """The reference scenario in the nonlinear closed loop (ideal actuators, the delay).

    Starts at the trim with the controller at its trim state; balancing: the gravity
    torque of seed 000's 0.5 mm slider offset as a constant disturbance torque; attitude:
    a 30 deg yaw step. Returns ``(t, dict)`` of the same signals as
    :func:`~airbearing.design.tuning.scenario_response` (deviations from the trim).
    """
    m = loop.model
    ctl = with_delay(loop.controller, m, loop.delay_samples, u_hold=loop.trim.u)
    dt = loop.dt
    n = int(round(t_end / dt))
    c_trim = loop.controller_trim()
    ctl = type(ctl)(
        ctl.name,
        ctl.function,
        np.concatenate([c_trim, ctl.c0[c_trim.size :]]),
        loop.gain_vector,
        ctl.gain_names,
        ctl.ref_names,
        ctl.extra_names,
    )
    nref = len(ctl.ref_names)
    V = np.zeros((m.ny + 3 + nref + 1, n))
    V[-1] = np.arange(n) * dt
    if loop.kind == "balancing":
        tb = m.testbed
        V[m.ny + 1] = tb.masses.mass_vec[0] * tb.gravity * 0.5e-3
        V[m.ny + 0] = -tb.masses.mass_vec[1] * tb.gravity * 0.5e-3
    else:
        yaw0 = float(loop.trim.x[0]) if m.dof == 1 else 0.0
        V[m.ny + 3 : m.ny + 3 + nref] = np.asarray(quat.from_yaw(yaw0 + math.radians(30.0)))[
            :, None
        ]
    F = closed_loop_rollout(m, ctl, n, 4)
    Z, R = F(np.concatenate([loop.trim.x, ctl.c0]), V, loop.p, ctl.gains)
    R = np.asarray(R).T
    x = R[:, : m.nx]
    u = R[:, m.nx + m.ny : m.nx + m.ny + m.nu]
    out = {}
    for ch in loop.channels:
        out[ch] = u[:, m.index(ch, "u")[0]] - loop.trim.value(ch)
    if m.dof == 1:
        out["true_yaw"] = x[:, 0] - loop.trim.x[0]
        out["true_wz"] = x[:, 1]
    else:
        dq = quat.qmul(quat.qconj(loop.trim.x[0:4]), x[:, 0:4])
        out["true_th_x"], out["true_th_y"], out["true_th_z"] = (2 * dq[:, 1:4]).T
    return np.arange(n) * dt, out


def _responses(rep: Report, loop: Loop, nonlinear: bool) -> float:
    """The scenario's linear response, the nonlinear closed loop overlaid; its end, s."""
    t_lin, y_lin = scenario_response(loop)
    t_end = float(t_lin[-1])
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    state_keys = [k for k in y_lin if k.startswith("true_")][:2]
    nl = None
    if nonlinear:
        t_nl, nl = nonlinear_scenario(loop, t_end)
    for k in state_keys:
        (ln,) = axes[0].plot(t_lin, np.degrees(y_lin[k]), label=f"{words(k)}, linear")
        if nl is not None and k in nl:
            axes[0].plot(
                t_nl, np.degrees(nl[k]), "--", color=ln.get_color(),
                label=f"{words(k)}, nonlinear",
            )  # fmt: skip
    for ch in loop.channels:
        (ln,) = axes[1].plot(t_lin, y_lin[ch], label=f"{words(ch)}, linear")
        if nl is not None:
            axes[1].plot(t_nl, nl[ch], "--", color=ln.get_color(), label=f"{words(ch)}, nonlinear")
    axes[0].set(xlabel="time (s)", ylabel="attitude deviation (deg or deg/s)")
    axes[1].set(xlabel="time (s)", ylabel="actuator deviation")
    axes[0].legend(fontsize=7)
    axes[1].legend(fontsize=7, ncol=2)
    scen = (
        "gravity torque of seed 000's 0.5 mm slider offset (step)"
        if loop.kind == "balancing"
        else "30 deg yaw step (seed 001 Table 5 manoeuvre)"
    )
    rep.figure(
        fig,
        f"Response to the {scen}: linear discrete model (solid) and the nonlinear "
        "CasADi closed loop with the same controller, ideal actuators and one sample of "
        "delay (dashed), as deviations from the trim.",
    )
    return t_end


def _disturbance_response(rep: Report, loop: Loop, t_end: float) -> None:
    """The attitude loop's linear response to a disturbance torque step."""
    cl = loop.closed_loop()
    t = np.arange(0, min(t_end, 60.0), loop.dt)
    u = np.zeros(cl.ninputs)
    u[list(cl.input_labels).index(loop.disturbances[-1])] = _DIST_TORQUE
    y = held_input_response(cl, u, t.size)
    fig, ax = plt.subplots(figsize=(10, 3))
    ax.plot(t, np.degrees(y[0]), label="yaw (deg)")
    ax.set(xlabel="time (s)", ylabel="yaw deviation (deg)")
    ax.legend(fontsize=8)
    rep.figure(
        fig,
        f"Linear response to a {_DIST_TORQUE:g} N m disturbance torque step "
        "(the residual torque of seed 000 Tables 1-2).",
    )
