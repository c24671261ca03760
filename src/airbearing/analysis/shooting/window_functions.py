"""The compiled functions of ONE window: the step, a window's start state, its residual,
Jacobian and outputs.

A large step (dof 3, ``CHAIN_MIN_INSTRUCTIONS``) and its Jacobian are compiled once per
structure and the window chained over them (:func:`_build_chained_window`); a small one
(dof 1) is compiled as whole windows (:func:`_build_whole_window`). Every function goes
through the one bounded cache (:mod:`.function_cache`); all windows of a problem are built
over these in :mod:`.problem_functions`.
"""

from __future__ import annotations

import copy
import weakref

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.shooting.function_cache import cached, compiled
from airbearing.models.model import Model
from airbearing.models.structure_cache import structure_key

#: RK4 sub-steps per sample of a replay: on the seed-004 free oscillation (rates to 1.5 rad/s,
#: 20 Hz) 2 sub-steps differ from 4 by 7e-7 rad/s RMS over 10 s, 1e-3 of a gyro's noise.
DEFAULT_SUBSTEPS = 2


#: Instructions of a step (``step_function``) from which a window is chained over the step
#: and its Jacobian compiled once per structure rather than compiled whole for every window
#: length. Measured (CPU, 2-core machine under load): the dof-3 platform's step (2,110
#: instructions) compiled whole took 1-3 min per window length and evaluates its window
#: Jacobian in 7.6 ms at 201 rows, chained 8.6 s once and 3.6 ms; a dof-1 step (63
#: instructions) compiles whole in about a second and runs 2x (Jacobian) to 15x (residual)
#: faster whole than chained through CasADi's virtual machine.
CHAIN_MIN_INSTRUCTIONS = 500


#: Order of the replay's Runge-Kutta step per number of rotational degrees of freedom: a
#: three-axis step (2,000 instructions per RK4 sub-step) takes Butcher's sixth-order
#: scheme, whose one step per sample at 50 Hz integrates seed 004's free oscillation more
#: accurately than four RK4 sub-steps (1.3e-9 against 2.3e-8 rad over a 2.5 min segment)
#: at 7/16 of the stages; a yaw bearing's small step keeps RK4.
REPLAY_ORDER = {1: 4, 3: 6}


def replay_order(model: Model) -> int:
    """The order of the replay's step of ``model`` (:data:`REPLAY_ORDER`)."""
    return REPLAY_ORDER.get(model.dof, 4)


def step_function(model: Model, substeps: int = DEFAULT_SUBSTEPS) -> ca.Function:
    """One sample with its own interval: ``(x, u, p, dt) -> x_next`` (:meth:`Model.step_dt`).

    The scheme of :meth:`Model.step` with ``dt`` an input, so a jittered log is integrated
    on its logged times, at the replay's order (:func:`replay_order`): RK4 for a yaw
    bearing, the sixth-order scheme with ``substeps`` sub-intervals for dof 3.
    """
    return model.step_dt(substeps, order=replay_order(model))


def delta_layout(model: Model, outputs: tuple) -> tuple[int, int, int, int]:
    """Entries of ``delta``, in this order: (attitude, rate, wheel speeds, lag).

    The wheel speeds' start is fitted when they are compared (output group ``ws``): a
    logged wheel speed is noisy like a logged rate, and a window started exactly at it
    would carry that sample's noise as an offset through the whole window.

    A dof-1 window fits its start yaw when the yaw is compared (attitude-only logs) or when
    a torque of the Model depends on it (:func:`yaw_acts`): a gyro log's ``yaw`` is the
    yaw "as the testbed knows it" (FORMATS.md; often the integral of a filtered gyro, seed
    001 eqs. 3 and 21), not the plant's, and a yaw-dependent torque (``spring_torque``,
    ``yaw_imbalance``, a field) taken at it would be wrong by its error.
    """
    if model.dof == 3:
        n_att = 3
    else:
        n_att = 1 if "yaw" in outputs or yaw_acts(model) or model in _START_YAW else 0
    n_rate = 3 if model.dof == 3 else 1
    return n_att, n_rate, n_wheel_speeds(model, outputs), len(model.lag_index)


def n_wheel_speeds(model: Model, outputs: tuple) -> int:
    """Wheel speeds compared (output group ``ws``): every wheel of ``[wheels]``, else 0."""
    if "ws" not in outputs:
        return 0
    return sum(1 for name in model.y_names if name.startswith("ws"))


def sigma_size(model: Model, outputs: tuple) -> int:
    """Entries of a window's ``sigma`` input: ``(rate, attitude)``, then each wheel speed's
    own noise level when they are compared (a rig's tachometers need not be alike)."""
    return 2 + n_wheel_speeds(model, outputs)


def layout_key(model: Model, outputs: tuple) -> tuple:
    """The part of a compiled function's cache key that the Model decides: its structure
    and its windows' :func:`delta_layout` (which :func:`yaw_acts` makes depend on values)."""
    return (structure_key(model), delta_layout(model, tuple(outputs)))


#: Points (yaw, rate, gimbals, inputs: unit normal draws) at which :func:`yaw_acts` looks.
_YAW_PROBES = 3
_YAW_ACTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Models whose windows fit their start yaw whatever their values (:func:`fitting_start_yaw`).
_START_YAW: weakref.WeakSet = weakref.WeakSet()


def yaw_acts(model: Model, p: np.ndarray | None = None) -> bool:
    """Whether a torque of a dof-1 Model depends on its yaw at its nominal parameters
    ``p0`` (``spring_torque`` or ``yaw_imbalance`` with a non-zero value, a field's torque),
    or at the parameters ``p`` when given.

    Not the structure alone: a discrepancy search holds every candidate at zero in one
    Model, and a start yaw that nothing depends on would be a direction no fit can fix.
    """
    if model.dof != 1:
        return False
    if p is None:
        if model not in _YAW_ACTS:
            _YAW_ACTS[model] = _depends_on_yaw(model, model.p0)
        return _YAW_ACTS[model]
    return _depends_on_yaw(model, np.asarray(p, dtype=float))


def _depends_on_yaw(model: Model, p: np.ndarray) -> bool:
    x = ca.SX.sym("x", model.nx)
    u, ps = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.n_p)
    dxdy = ca.jacobian(model.f(x, u, ps), x[model.index("yaw")[0]])
    fn = ca.Function("dxdot_dyaw", [x, u, ps], [dxdy])
    rng = np.random.default_rng(0)
    X = rng.standard_normal((model.nx, _YAW_PROBES))
    U = rng.standard_normal((model.nu, _YAW_PROBES))
    D = np.asarray(fn.map(_YAW_PROBES)(X, U, np.tile(p[:, None], _YAW_PROBES)))
    return bool(np.any(D != 0))


def fitting_start_yaw(model: Model) -> Model:
    """``model`` (a dof-1 Model), as a copy whose windows fit their start yaw whatever its
    nominal values (:func:`delta_layout`).

    For a fit that moves a yaw torque away from the Model's nominal values (a discrepancy
    search's candidate ``spring_torque``, held at zero in the Model): the start yaw is then
    a direction the fit fixes, as long as the torque's value stays away from zero. The
    same Model (itself) for dof 3 and for a Model whose yaw torque acts already.
    """
    if model.dof != 1 or yaw_acts(model) or model in _START_YAW:
        return model
    other = copy.copy(model)
    _START_YAW.add(other)
    return other


def _window_functions(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    key = ("window", layout_key(model, outputs), L, K, outputs, substeps, jit, link)
    # whole windows are compiled (linked ones but their outputs): a new process loads them
    whole = step_instructions(model, substeps) < CHAIN_MIN_INSTRUCTIONS
    return cached(
        key,
        lambda: _build_window(model, L, K, outputs, substeps, jit, link),
        disk=whole and not link and jit is not False,
    )


def step_instructions(model: Model, substeps: int) -> int:
    """Instructions of :func:`step_function` (known to a new process without building it)."""
    key = ("step size", structure_key(model), substeps)
    return cached(key, lambda: (step_function(model, substeps).n_instructions(),), disk=True)[0]


def start_function(model: Model, outputs: tuple) -> ca.Function:
    """``(delta, x_meas) -> x0``: a window's initial state from its estimate (module doc)."""
    key = ("start", layout_key(model, outputs), tuple(outputs))
    return cached(key, lambda: _build_start(model, tuple(outputs)))


def _build_start(model: Model, outputs: tuple) -> ca.Function:
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    d = ca.SX.sym("delta", nd)
    xm = ca.SX.sym("x_meas", model.nx - n_lag)
    if model.dof == 3:
        rate0 = xm[4:7] + d[3:6]
        parts = [quat.qmul(xm[0:4], quat.qexp(d[0:3])), rate0, xm[7:]]
    else:
        yaw0 = xm[0] + d[0] if n_att else xm[0]
        rate0 = xm[1] + d[n_att]
        parts = [yaw0, rate0, xm[2:]]
    if n_ws:
        # the wheel speeds (the last plant states, FORMATS.md) start near their logged ones
        nxp, i0 = model.nx - n_lag, n_att + n_rate
        other = xm[n_att_states(model) + n_rate : nxp - n_ws]
        parts[-1] = ca.vertcat(other, xm[nxp - n_ws :] + d[i0 : i0 + n_ws])
    if n_lag:
        # the lagged gyro starts near the start rate, free per window
        parts.append(rate0 + d[n_att + n_rate + n_ws :])
    return ca.Function("x0", [d, xm], [ca.vertcat(*parts)])


def n_att_states(model: Model) -> int:
    """Attitude entries of the state: the quaternion (dof 3) or the yaw (dof 1)."""
    return 4 if model.dof == 3 else 1


def _step_functions(model: Model, substeps: int, jit) -> tuple:
    """``(step, step_jac)`` compiled once per structure and sub-steps (any window length,
    slot count, output groups): ``(x, u, p, dt) -> x_next`` and ``-> (x_next, d x_next /
    d[x; p])``."""
    key = ("step", structure_key(model), substeps, jit)

    def build():
        step = step_function(model, substeps)
        x, u = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu)
        p, dt = ca.SX.sym("p", model.n_p), ca.SX.sym("dt")
        xn = step(x, u, p, dt)
        jac = ca.Function(
            "step_jac", [x, u, p, dt], [xn, ca.jacobian(xn, ca.vertcat(x, p))],
            ["x", "u", "p", "dt"], ["x_next", "jac"],
        )  # fmt: skip
        return compiled(step, jit=jit), compiled(jac, jit=jit)

    return cached(key, build, disk=jit is not False)


def _sample_functions(model: Model, outputs: tuple, jit) -> tuple:
    """``(res, res_jac)`` of one sample, compiled once per structure and output groups:
    ``(x, u, p, weight, w, q, yaw, sigma) -> r_g`` per group ``g`` of ``outputs`` (the
    window's residual, module doc), and the same followed by each ``d r_g / d[x; p]``.
    ``w`` holds the measured rates, then the measured wheel speeds when ``ws`` is
    compared (``sigma`` then has their levels, one per wheel, from its third entry)."""
    key = ("sample", structure_key(model), outputs, jit)

    def build():
        dof, na = model.dof, delta_layout(model, outputs)[1]
        n_ws = n_wheel_speeds(model, outputs)
        x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.n_p)
        m, w, q = ca.SX.sym("weight"), ca.SX.sym("w", na + n_ws), ca.SX.sym("q", 4)
        yw, sig = ca.SX.sym("yaw"), ca.SX.sym("sigma", sigma_size(model, outputs))
        y = model.h(x, u, p)
        res = []
        if "rate" in outputs:
            rows = model.index(["wx", "wy", "wz"] if dof == 3 else ["wz"], "y")
            res.append(m * (w[:na] - y[rows]) / sig[0])
        if "quat" in outputs:
            e = quat.qmul(quat.qconj(y[model.index(["qw", "qx", "qy", "qz"], "y")]), q)
            res.append(m * 2 * ca.sign(e[0] + 1e-300) * e[1:4] / sig[1])
        if "yaw" in outputs:
            res.append(m * (yw - y[model.index(["yaw"], "y")[0]]) / sig[1])
        if n_ws:
            rows = model.index([f"ws{i}" for i in range(1, n_ws + 1)], "y")
            res.append(m * (w[na:] - y[rows]) / sig[2:])  # each wheel its own level
        ins = [x, u, p, m, w, q, yw, sig]
        xp = ca.vertcat(x, p)
        fr = ca.Function("sample_r", ins, res)
        frj = ca.Function("sample_rj", ins, [*res, *[ca.jacobian(g, xp) for g in res]])
        return compiled(fr, jit=jit), compiled(frj, jit=jit)

    return cached(key, build, disk=jit is not False)


def _build_window(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    """``(window_r, window_rj, window_y)`` of one window of ``L`` rows: chained over the
    step compiled once per structure (:func:`_build_chained_window`) when the step is large,
    else whole windows compiled to C (:func:`_build_whole_window`)."""
    if step_instructions(model, substeps) >= CHAIN_MIN_INSTRUCTIONS:
        return _build_chained_window(model, L, K, outputs, substeps, jit, link)
    return _build_whole_window(model, L, K, outputs, substeps, jit, link)


def _build_whole_window(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    """The window functions compiled to C as whole windows (the derivatives inside), for a
    small step (:data:`CHAIN_MIN_INSTRUCTIONS`)."""
    dof = model.dof
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    nx_plant = model.nx - n_lag
    na = n_rate
    x0_fn = start_function(model, outputs)
    qa, qb = ca.SX.sym("qa", 4), ca.SX.sym("qb", 4)
    e = quat.qmul(quat.qconj(qa), qb)
    att_fn = ca.Function("att_err", [qa, qb], [2 * ca.sign(e[0] + 1e-300) * e[1:4]])

    D = ca.MX.sym("delta", nd)
    XM = ca.MX.sym("x_meas0", nx_plant)
    U = ca.MX.sym("U", model.nu, L)
    DT = ca.MX.sym("dt", 1, L - 1)
    M = ca.MX.sym("weight", 1, L)
    W = ca.MX.sym("W_meas", na + n_ws, L)
    Q = ca.MX.sym("Q_meas", 4, L)
    YW = ca.MX.sym("yaw_meas", 1, L)
    PB = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    TH = ca.MX.sym("theta", K)
    SIG = ca.MX.sym("sigma", sigma_size(model, outputs))
    P = PB + ca.mtimes(S, TH) if K else PB
    X0 = x0_fn(D, XM)
    step = step_function(model, substeps)
    X = step.mapaccum("rollout", L - 1, [0], [0])(X0, U[:, : L - 1], P, DT)
    X_all = ca.horzcat(X0, X)
    Y = model.h.map(L)(X_all, U, P)
    res = []
    if "rate" in outputs:
        rows = model.index(["wx", "wy", "wz"] if dof == 3 else ["wz"], "y")
        res.append(ca.vec(ca.repmat(M, na, 1) * (W[:na, :] - Y[rows, :]) / SIG[0]))
    if "quat" in outputs:
        rows = model.index(["qw", "qx", "qy", "qz"], "y")
        res.append(ca.vec(ca.repmat(M, 3, 1) * att_fn.map(L)(Y[rows, :], Q) / SIG[1]))
    if "yaw" in outputs:
        row = model.index(["yaw"], "y")[0]
        res.append(ca.vec(M * (YW - Y[row, :]) / SIG[1]))
    if n_ws:
        rows = model.index([f"ws{i}" for i in range(1, n_ws + 1)], "y")
        sw = ca.repmat(SIG[2:], 1, L)  # each wheel over its own noise level
        res.append(ca.vec(ca.repmat(M, n_ws, 1) * (W[na:, :] - Y[rows, :]) / sw))
    r = ca.vertcat(*res)
    ins = [D, XM, U, DT, M, W, Q, YW, PB, S, TH, SIG]
    names = [
        "delta",
        "x_meas0",
        "U",
        "dt",
        "weight",
        "W",
        "Q",
        "YAW",
        "p_base",
        "S",
        "theta",
        "sigma",
    ]
    if link:
        # the state at the row the selector E picks (the next window's first row)
        E = ca.MX.sym("end", 1, L)
        xe = ca.mtimes(X_all, E.T)
        ins, names = [*ins, E], [*names, "end"]
        Jall = ca.jacobian(ca.vertcat(r, xe), ca.vertcat(TH, D))
        n_r = r.shape[0]
        win_r = ca.Function("window_r", ins, [r, xe], names, ["r", "x_end"])
        win_rj = ca.Function(
            "window_rj",
            ins,
            [r, Jall[:n_r, :], xe, Jall[n_r:, :]],
            names,
            ["r", "J", "x_end", "dx_end"],
        )
    else:
        win_r = ca.Function("window_r", ins, [r], names, ["r"])
        win_rj = ca.Function(
            "window_rj", ins, [r, ca.jacobian(r, ca.vertcat(TH, D))], names, ["r", "J"]
        )
    win_y = ca.Function("window_y", [D, XM, U, DT, PB, S, TH], [Y])
    # the residual, its Jacobian and the outputs compiled to C as whole windows (the
    # derivatives are inside), cached on disk: a new process loads them. Linked windows
    # (the output-error fit) never replay outputs in bulk: their outputs stay in the
    # virtual machine (same values, one compilation less per structure)
    win_y = compiled(win_y, jit=False if link else jit)
    return compiled(win_r, jit=jit), compiled(win_rj, jit=jit), win_y


def _build_chained_window(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    """The window functions of :func:`_window_functions` (CasADi's virtual machine) over
    the compiled step and sample functions.

    The Jacobian in ``v = [theta; delta]`` follows the rollout by the chain rule, ``S_{k+1}
    = d x_next / d[x; p] [S_k; d p / d v]`` from ``S_0 = d x_0 / d v``, and each sample's
    residual rows are ``d r / d[x; p] [S_k; d p / d v]``: the same numbers as CasADi's
    forward derivative of the whole window (to round-off), with only the step's and the
    sample's Jacobians compiled, once per structure. Compiling whole windows (the step's
    forward derivative in 12 directions: 117,000 lines of C for dof 3) took minutes for
    every new window length.
    """
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    nx, n_p, na = model.nx, model.n_p, n_rate + n_ws
    nv = K + nd
    step, step_jac = _step_functions(model, substeps, jit)
    sample_r, sample_rj = _sample_functions(model, outputs, jit)
    ng = len(outputs)

    # one step of the state and its sensitivity, one sample's residual rows
    x, Sx = ca.MX.sym("x", nx), ca.MX.sym("Sx", nx, nv)
    u, p, dt = ca.MX.sym("u", model.nu), ca.MX.sym("p", n_p), ca.MX.sym("dt")
    Sp = ca.MX.sym("Sp", n_p, nv)
    xn, A = step_jac(x, u, p, dt)
    sens = ca.Function("step_sens", [x, Sx, u, p, Sp, dt], [xn, ca.mtimes(A, ca.vertcat(Sx, Sp))])
    sm, sw, sq = ca.MX.sym("weight"), ca.MX.sym("w", na), ca.MX.sym("q", 4)
    syw, ssig = ca.MX.sym("yaw"), ca.MX.sym("sigma", sigma_size(model, outputs))
    sins = [x, u, p, sm, sw, sq, syw, ssig]
    out = sample_rj(*sins)
    # each group's rows transposed: a map puts the samples side by side
    rows_t = [ca.transpose(ca.mtimes(g, ca.vertcat(Sx, Sp))) for g in out[ng:]]
    sample_j = ca.Function("sample_j", [*sins, Sx, Sp], [*out[:ng], *rows_t])

    x0_fn = start_function(model, outputs)
    D = ca.MX.sym("delta", nd)
    XM = ca.MX.sym("x_meas0", nx - n_lag)
    U = ca.MX.sym("U", model.nu, L)
    DT = ca.MX.sym("dt", 1, L - 1)
    M = ca.MX.sym("weight", 1, L)
    W = ca.MX.sym("W_meas", na, L)
    Q = ca.MX.sym("Q_meas", 4, L)
    YW = ca.MX.sym("yaw_meas", 1, L)
    PB = ca.MX.sym("p_base", n_p)
    S = ca.MX.sym("S", n_p, K)
    TH = ca.MX.sym("theta", K)
    SIG = ca.MX.sym("sigma", sigma_size(model, outputs))
    P = PB + ca.mtimes(S, TH) if K else PB
    X0 = x0_fn(D, XM)
    data = [M, W, Q, YW, SIG]
    ins = [D, XM, U, DT, M, W, Q, YW, PB, S, TH, SIG]
    names = ["delta", "x_meas0", "U", "dt", "weight", "W", "Q", "YAW", "p_base", "S",
             "theta", "sigma"]  # fmt: skip

    X = step.mapaccum("rollout", L - 1, [0], [0])(X0, U[:, : L - 1], P, DT)
    X_all = ca.horzcat(X0, X)
    res = sample_r.map(L)(X_all, U, P, *data)
    res = [res] if isinstance(res, ca.MX) else res
    r = ca.vertcat(*[ca.vec(g) for g in res])

    SP = ca.horzcat(S, ca.MX(n_p, nd))  # d p / d v
    S0 = ca.densify(ca.horzcat(ca.MX(nx, K), ca.jacobian(X0, D)))  # d x_0 / d v
    Xs, Ss = sens.mapaccum("rollout_sens", L - 1, [0, 1], [0, 1])(X0, S0, U[:, : L - 1], P, SP, DT)
    Xj, Sj = ca.horzcat(X0, Xs), ca.horzcat(S0, Ss)
    outj = sample_j.map(L)(Xj, U, P, *data, Sj, SP)
    rj = ca.vertcat(*[ca.vec(g) for g in outj[:ng]])
    J = ca.vertcat(*[ca.transpose(g) for g in outj[ng:]])
    if link:
        # the state at the row the selector E picks (the next window's first row)
        E = ca.MX.sym("end", 1, L)
        ins, names = [*ins, E], [*names, "end"]
        win_r = ca.Function("window_r", ins, [r, ca.mtimes(X_all, E.T)], names, ["r", "x_end"])
        win_rj = ca.Function(
            "window_rj",
            ins,
            [rj, J, ca.mtimes(Xj, E.T), ca.mtimes(Sj, ca.kron(E.T, ca.DM.eye(nv)))],
            names,
            ["r", "J", "x_end", "dx_end"],
        )
    else:
        win_r = ca.Function("window_r", ins, [r], names, ["r"])
        win_rj = ca.Function("window_rj", ins, [rj, J], names, ["r", "J"])
    win_y = ca.Function("window_y", [D, XM, U, DT, PB, S, TH], [model.h.map(L)(X_all, U, P)])
    return win_r, win_rj, win_y
