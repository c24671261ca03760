"""The sensor side of a testbed's Model in CasADi: the ``sensor_lag`` states (their names,
their exact update over a sub-interval and their steady start) and the measurement
``h(x, u, p) -> y``.
"""

from __future__ import annotations

import casadi as ca


def _lag_states(ctx, dof: int, xp, u, p, f_plant):
    """The sensor lags' state names, the full state, their exact update over a sub-interval
    and their steady start."""
    lag_syms = [s for s, _, _ in ctx.lag_states]
    lag_names = []
    for k, _ in enumerate(lag_syms):
        axes_names = ["wx", "wy", "wz"] if dof == 3 else ["wz"]
        lag_names += [f"lag_{a}" if k == 0 else f"lag{k}_{a}" for a in axes_names]
    x_all = ca.vertcat(xp, *lag_syms)
    # exact update of the lag states over one sub-interval h for a source varying linearly
    # from a to b (first-order hold): y+ = b - tau s + (y - a + tau s) exp(-h/tau), s = (b-a)/h
    xa, xb, hh = ca.SX.sym("xa", xp.shape[0]), ca.SX.sym("xb", xp.shape[0]), ca.SX.sym("h")
    lag_in = ca.vertcat(*lag_syms) if lag_syms else ca.SX(0, 1)
    lag_next = []
    for s, src, tau in ctx.lag_states:
        src_fn = ca.Function("src", [xp, p], [src])
        a, b = src_fn(xa, p), src_fn(xb, p)
        tau_slope = tau * (b - a) / hh
        decay = ca.if_else(tau > 0, ca.exp(-hh / ca.fmax(tau, 1e-12)), 0)
        lag_next.append(b - tau_slope + (s - a + tau_slope) * decay)
    lag_fn = ca.Function(
        "lag", [xa, xb, lag_in, p, hh], [ca.vertcat(*lag_next) if lag_next else ca.SX(0, 1)]
    )
    # a lag that has followed the rate for a while: steady state of a ramp, y = src - tau src'
    src_dot = [ca.jtimes(src, xp, f_plant(xp, u, p)) for _, src, _ in ctx.lag_states]
    lag0 = [src - tau * sd for (_, src, tau), sd in zip(ctx.lag_states, src_dot, strict=True)]
    lag_init = ca.Function(
        "lag_init",
        [xp, u, p],
        [ca.vertcat(*lag0) if lag_syms else ca.SX(0, 1)],
        ["x_plant", "u", "p"],
        ["lag0"],
    )
    return lag_names, x_all, lag_fn, lag_init


def _measurement(kind: str, dof: int, ctx, q, X, x_all, u, p, P, n_wheels: int = 0):
    """The output names and ``h(x, u, p) -> y``: attitude, measured rate, gravity direction
    (dof 3), gimbal angles (CMG) and wheel speeds (``[wheels]``)."""
    if dof == 3:
        y = [q, ctx.rate_measured, ctx.g_body / P["gravity"]]
        y_names = ["qw", "qx", "qy", "qz", "wx", "wy", "wz", "gx", "gy", "gz"]
    else:
        y = [ctx.yaw, ctx.rate_measured]
        y_names = ["yaw", "wz"]
    if kind == "cmg":
        y.append(ca.vertcat(*[X[f"d{i}"] for i in range(1, 5)]))
        y_names += ["d1", "d2", "d3", "d4"]
    if n_wheels:
        y.append(ctx.wheel_speeds)
        y_names += [f"ws{i}" for i in range(1, n_wheels + 1)]
    h_fn = ca.Function("h", [x_all, u, p], [ca.vertcat(*y)], ["x", "u", "p"], ["y"])
    return y_names, h_fn
