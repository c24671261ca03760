"""The sensor side of a testbed's Model in CasADi: the ``sensor_lag`` states (their names,
their fourth-order update over a sub-interval and their steady start) and the measurement
``h(x, u, p) -> y``.
"""

from __future__ import annotations

import casadi as ca


def _lag_states(ctx, dof: int, xp, u, p, f_plant):
    """The sensor lags' state names, the full state, their update over a sub-interval
    (exact for a cubic source: fourth order) and their steady start."""
    lag_syms = [s for s, _, _ in ctx.lag_states]
    lag_names = []
    for k, _ in enumerate(lag_syms):
        axes_names = ["wx", "wy", "wz"] if dof == 3 else ["wz"]
        lag_names += [f"lag_{a}" if k == 0 else f"lag{k}_{a}" for a in axes_names]
    x_all = ca.vertcat(xp, *lag_syms)
    # exact update of the lag states over one sub-interval h for a source following the
    # cubic Hermite interpolant of its end values a, b and end slopes da, db (from the
    # plant's xdot at both ends), so the update is fourth order like the RK4 step it rides
    # on (a linear source made it second order). With P(s) = a + da s + c2 s^2 + c3 s^3 the
    # particular solution of y' = (P - y)/tau is P - tau P' + tau^2 P'' - tau^3 P''', so
    # y+ = b - tau db + 6 tau^2 c3 h + (y - a + tau da) e + (2 tau^2 c2 - 6 tau^3 c3)(1 - e),
    # e = exp(-h/tau); tau = 0 gives y+ = b (the lag reads the rate).
    xa, xb, hh = ca.SX.sym("xa", xp.shape[0]), ca.SX.sym("xb", xp.shape[0]), ca.SX.sym("h")
    fa, fb = ca.SX.sym("fa", xp.shape[0]), ca.SX.sym("fb", xp.shape[0])
    lag_in = ca.vertcat(*lag_syms) if lag_syms else ca.SX(0, 1)
    lag_next = []
    for s, src, tau in ctx.lag_states:
        src_fn = ca.Function("src", [xp, p], [src])
        src_jac = ca.Function("src_jac", [xp, p], [ca.jacobian(src, xp)])
        a, b = src_fn(xa, p), src_fn(xb, p)
        da, db = ca.mtimes(src_jac(xa, p), fa), ca.mtimes(src_jac(xb, p), fb)
        chord = (b - a) / hh
        c2 = (3 * chord - 2 * da - db) / hh
        c3 = (da + db - 2 * chord) / hh**2
        decay = ca.if_else(tau > 0, ca.exp(-hh / ca.fmax(tau, 1e-12)), 0)
        lag_next.append(
            b
            - tau * db
            + 6 * tau**2 * c3 * hh
            + (s - a + tau * da) * decay
            + (2 * tau**2 * c2 - 6 * tau**3 * c3) * (1 - decay)
        )
    lag_fn = ca.Function(
        "lag",
        [xa, xb, fa, fb, lag_in, p, hh],
        [ca.vertcat(*lag_next) if lag_next else ca.SX(0, 1)],
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
