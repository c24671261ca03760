"""Compiled functions of the shooting engine: one window, all windows, the IPOPT solver.

One bounded cache (``CACHE_SIZE`` entries) keyed by the Model's STRUCTURE (the package's
one key, :func:`airbearing.models.structure_cache.structure_key`), the window length, the
number of parameter slots, the output groups and whether windows are linked; compiled
functions go through the on-disk cache of :mod:`airbearing.models.compiled` (a new process
loads them): a large step (dof 3) and its Jacobian once per structure, the window chained
over them; a small one (dof 1) as whole windows (``CHAIN_MIN_INSTRUCTIONS``). The constrained solver
(linked windows, inequalities) is in :mod:`.constrained`, in the same cache.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import casadi as ca
import numpy as np
import scipy.sparse as sp

from airbearing import quaternion as quat
from airbearing.models.model import Model
from airbearing.models.structure_cache import structure_key

#: RK4 sub-steps per sample of a replay: on the seed-004 free oscillation (rates to 1.5 rad/s,
#: 20 Hz) 2 sub-steps differ from 4 by 7e-7 rad/s RMS over 10 s, 1e-3 of a gyro's noise.
DEFAULT_SUBSTEPS = 2
#: Free-parameter slots of a fit: unused slots are fixed at zero, so every fit with up to
#: this many parameters shares one compiled Jacobian (one number of AD directions).
THETA_SLOTS = 6
#: IPOPT iteration limit (Gauss-Newton on scaled variables converges in a few).
IPOPT_MAX_ITER = 80
#: IPOPT tolerance (scaled variables: a step of 1 moves the residual by ~1 sigma).
IPOPT_TOL = 1e-6
#: IPOPT's acceptable-level test with the objective's change in it: for 2 iterations in a row
#: the scaled optimality error below 1e-4 AND the objective (half the chi-square) changed by
#: less than 1e-10 of itself (4e-7 of a chi-square of 4,300: far below one unit). At such
#: points of a warm-started fit the round-off of a long rollout's gradient kept the dual
#: infeasibility above ``IPOPT_TOL`` and IPOPT backtracked 15-27 times per iteration
#: (docs/benchmarks.md, "Where a dof-3 search spends its time").
OBJECTIVE_STOP = {
    "ipopt.acceptable_tol": 1e-4,
    "ipopt.acceptable_obj_change_tol": 1e-10,
    "ipopt.acceptable_iter": 2,
}
#: Relative eigenvalue of the reduced Fisher matrix below which a parameter is not identifiable.
FISHER_RCOND = 1e-10
#: Largest number of compiled function sets kept per process.
CACHE_SIZE = 48
#: Output groups a window can compare.
OUTPUTS = ("rate", "quat", "yaw")
#: Instructions of a step (``step_function``) from which a window is chained over the step
#: and its Jacobian compiled once per structure rather than compiled whole for every window
#: length. Measured (CPU, 2-core machine under load): the dof-3 platform's step (2,110
#: instructions) compiled whole took 1-3 min per window length and evaluates its window
#: Jacobian in 7.6 ms at 201 rows, chained 8.6 s once and 3.6 ms; a dof-1 step (63
#: instructions) compiles whole in about a second and runs 2x (Jacobian) to 15x (residual)
#: faster whole than chained through CasADi's virtual machine.
CHAIN_MIN_INSTRUCTIONS = 500

# ----------------------------------------------------------------------------
# compiled functions: one bounded cache keyed by structure


def jit_available() -> bool:
    """True when a C compiler is available to compile the window functions."""
    from airbearing.models.compiled import compiler

    return compiler() is not None


_CACHE: OrderedDict = OrderedDict()


def _cached(key, build):
    """Bounded LRU of compiled functions (``CACHE_SIZE`` entries)."""
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    value = build()
    _CACHE[key] = value
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return value


def step_function(model: Model, substeps: int = DEFAULT_SUBSTEPS) -> ca.Function:
    """One sample with its own interval: ``(x, u, p, dt) -> x_next`` (:meth:`Model.step_dt`).

    The same scheme as :meth:`Model.step` with ``dt`` an input, so a jittered log is
    integrated on its logged times.
    """
    return model.step_dt(substeps)


def compiled(fn: ca.Function, *, jit: bool | None = None, progress=None) -> ca.Function:
    """``fn`` compiled to C through the on-disk cache (:func:`airbearing.models.compiled.compiled`).

    Parameters
    ----------
    fn : casadi.Function
        Any Function CasADi can generate C for, its outputs holding every derivative needed.
    jit : bool, optional
        False: return ``fn`` (CasADi's virtual machine, same values); default: compile
        when a C compiler is available.
    progress : callable, optional
        Told when a compilation starts (once per structure and machine).
    """
    if jit is False:
        return fn
    from airbearing.models.compiled import compiled as disk_compiled

    return disk_compiled(fn, key="airbearing.analysis.shooting v1", progress=progress)


def delta_layout(model: Model, outputs: tuple) -> tuple[int, int, int]:
    """Entries of ``delta``: (attitude, rate, lag)."""
    n_att = 3 if model.dof == 3 else (1 if "yaw" in outputs else 0)
    n_rate = 3 if model.dof == 3 else 1
    return n_att, n_rate, len(model.lag_index)


def _window_functions(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    key = ("window", structure_key(model), L, K, outputs, substeps, jit, link)
    return _cached(key, lambda: _build_window(model, L, K, outputs, substeps, jit, link))


def start_function(model: Model, outputs: tuple) -> ca.Function:
    """``(delta, x_meas) -> x0``: a window's initial state from its estimate (module doc)."""
    key = ("start", structure_key(model), tuple(outputs))
    return _cached(key, lambda: _build_start(model, tuple(outputs)))


def _build_start(model: Model, outputs: tuple) -> ca.Function:
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    d = ca.SX.sym("delta", nd)
    xm = ca.SX.sym("x_meas", model.nx - n_lag)
    if model.dof == 3:
        rate0 = xm[4:7] + d[3:6]
        parts = [quat.qmul(xm[0:4], quat.qexp(d[0:3])), rate0, xm[7:]]
    else:
        yaw0 = xm[0] + d[0] if n_att else xm[0]
        rate0 = xm[1] + d[n_att]
        parts = [yaw0, rate0, xm[2:]]
    if n_lag:
        # the lagged gyro starts near the start rate, free per window
        parts.append(rate0 + d[n_att + n_rate :])
    return ca.Function("x0", [d, xm], [ca.vertcat(*parts)])


def _link_function(model: Model, K: int, outputs: tuple) -> ca.Function:
    """Continuity defect between a window's end and the next window's start.

    ``(x_end, dx_end, delta_next, x_meas_next, sigma) -> (c, dc/d[theta; delta], dc/d delta_next)``
    with ``dx_end`` the end state's Jacobian in ``[theta; delta]`` of its own window. One
    entry per entry of ``delta`` (the states a window's ``delta`` sets): the small rotation
    ``2 vec(conj(q_end) (x) q_next)`` (dof 3) or the yaw difference, over ``sigma_att``; the
    rate and lagged-rate differences over ``sigma_rate`` (defects in noise units).
    """
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    nx = model.nx
    xe = ca.SX.sym("x_end", nx)
    dxe = ca.SX.sym("dx_end", nx, K + nd)
    dn = ca.SX.sym("delta_next", nd)
    xm = ca.SX.sym("x_meas_next", nx - n_lag)
    sig = ca.SX.sym("sigma", 2)
    xn = start_function(model, outputs)(dn, xm)
    rate = list(range(4, 7)) if model.dof == 3 else [1]
    parts = []
    if model.dof == 3:
        e = quat.qmul(quat.qconj(xe[0:4]), xn[0:4])
        parts.append(2 * ca.sign(e[0] + 1e-300) * e[1:4] / sig[1])
    elif n_att:
        parts.append((xn[0] - xe[0]) / sig[1])
    parts.append((xn[rate] - xe[rate]) / sig[0])
    if n_lag:
        lag = list(model.lag_index)
        parts.append((xn[lag] - xe[lag]) / sig[0])
    c = ca.vertcat(*parts)
    return ca.Function(
        "link",
        [xe, dxe, dn, xm, sig],
        [c, ca.mtimes(ca.jacobian(c, xe), dxe), ca.jacobian(c, dn)],
    )


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

    return _cached(key, build)


def _sample_functions(model: Model, outputs: tuple, jit) -> tuple:
    """``(res, res_jac)`` of one sample, compiled once per structure and output groups:
    ``(x, u, p, weight, w, q, yaw, sigma) -> r_g`` per group ``g`` of ``outputs`` (the
    window's residual, module doc), and the same followed by each ``d r_g / d[x; p]``."""
    key = ("sample", structure_key(model), outputs, jit)

    def build():
        dof, na = model.dof, delta_layout(model, outputs)[1]
        x, u, p = ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.n_p)
        m, w, q = ca.SX.sym("weight"), ca.SX.sym("w", na), ca.SX.sym("q", 4)
        yw, sig = ca.SX.sym("yaw"), ca.SX.sym("sigma", 2)
        y = model.h(x, u, p)
        res = []
        if "rate" in outputs:
            rows = model.index(["wx", "wy", "wz"] if dof == 3 else ["wz"], "y")
            res.append(m * (w - y[rows]) / sig[0])
        if "quat" in outputs:
            e = quat.qmul(quat.qconj(y[model.index(["qw", "qx", "qy", "qz"], "y")]), q)
            res.append(m * 2 * ca.sign(e[0] + 1e-300) * e[1:4] / sig[1])
        if "yaw" in outputs:
            res.append(m * (yw - y[model.index(["yaw"], "y")[0]]) / sig[1])
        ins = [x, u, p, m, w, q, yw, sig]
        xp = ca.vertcat(x, p)
        fr = ca.Function("sample_r", ins, res)
        frj = ca.Function("sample_rj", ins, [*res, *[ca.jacobian(g, xp) for g in res]])
        return compiled(fr, jit=jit), compiled(frj, jit=jit)

    return _cached(key, build)


def _build_window(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    """``(window_r, window_rj, window_y)`` of one window of ``L`` rows: chained over the
    step compiled once per structure (:func:`_build_chained_window`) when the step is large,
    else whole windows compiled to C (:func:`_build_whole_window`)."""
    if step_function(model, substeps).n_instructions() >= CHAIN_MIN_INSTRUCTIONS:
        return _build_chained_window(model, L, K, outputs, substeps, jit, link)
    return _build_whole_window(model, L, K, outputs, substeps, jit, link)


def _build_whole_window(
    model: Model, L: int, K: int, outputs: tuple, substeps: int, jit, link: bool = False
):
    """The window functions compiled to C as whole windows (the derivatives inside), for a
    small step (:data:`CHAIN_MIN_INSTRUCTIONS`)."""
    dof = model.dof
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
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
    W = ca.MX.sym("W_meas", na, L)
    Q = ca.MX.sym("Q_meas", 4, L)
    YW = ca.MX.sym("yaw_meas", 1, L)
    PB = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    TH = ca.MX.sym("theta", K)
    SIG = ca.MX.sym("sigma", 2)
    P = PB + ca.mtimes(S, TH) if K else PB
    X0 = x0_fn(D, XM)
    step = step_function(model, substeps)
    X = step.mapaccum("rollout", L - 1, [0], [0])(X0, U[:, : L - 1], P, DT)
    X_all = ca.horzcat(X0, X)
    Y = model.h.map(L)(X_all, U, P)
    res = []
    if "rate" in outputs:
        rows = model.index(["wx", "wy", "wz"] if dof == 3 else ["wz"], "y")
        res.append(ca.vec(ca.repmat(M, na, 1) * (W - Y[rows, :]) / SIG[0]))
    if "quat" in outputs:
        rows = model.index(["qw", "qx", "qy", "qz"], "y")
        res.append(ca.vec(ca.repmat(M, 3, 1) * att_fn.map(L)(Y[rows, :], Q) / SIG[1]))
    if "yaw" in outputs:
        row = model.index(["yaw"], "y")[0]
        res.append(ca.vec(M * (YW - Y[row, :]) / SIG[1]))
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
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    nx, n_p, na = model.nx, model.n_p, n_rate
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
    syw, ssig = ca.MX.sym("yaw"), ca.MX.sym("sigma", 2)
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
    SIG = ca.MX.sym("sigma", 2)
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


def _data_shapes(model: Model, L: int, nw: int, na: int, link: bool = False) -> list:
    """Pieces of the data vector; ``sigma`` (2) is always the last one."""
    nx_plant = model.nx - len(model.lag_index)
    return [
        (nx_plant, nw),
        (model.nu, L * nw),
        (1, (L - 1) * nw),
        (1, L * nw),
        (na, L * nw),
        (4, L * nw),
        (1, L * nw),
        *([(1, L * nw)] if link else []),  # end-row selector of each window
        (2, 1),
    ]


def _problem_functions(model, L, nw, K, outputs, substeps, jit, link=False):
    """``(fr, fj, fy)`` of :func:`_build_problem`, from the one bounded cache."""
    key = ("problem", structure_key(model), L, nw, K, outputs, substeps, jit, link)
    return _cached(key, lambda: _build_problem(model, L, nw, K, outputs, substeps, jit, link))


def window_jacobian(model, L, nw, K, outputs, substeps, jit, link=False) -> WindowJacobian:
    """The :class:`WindowJacobian` ``fj`` of :func:`_problem_functions`."""
    return _problem_functions(model, L, nw, K, outputs, substeps, jit, link)[1]


class WindowJacobian:
    """The residual and its Jacobian in ``v = [theta; vec(delta)]`` from the windows' own
    blocks: the compiled window function runs on ``THREADS`` windows at a time, each call
    writing straight into its windows' slices of the result (:meth:`casadi.Function.buffer`),
    and NumPy places the blocks in the sparse matrix. On an hour of 50 Hz pieces the same
    in one CasADi map cost 0.6 GB for the map's output pattern and work vectors, and its
    assembly in CasADi's virtual machine 1 GB more.

    Attributes
    ----------
    shape : tuple of int
        ``(m nw, K + nd nw)``, the Jacobian's shape.
    """

    def __init__(self, win_rj: ca.Function, nw: int, K: int, shapes: list, defects=None):
        self.win_rj, self.nw, self.K, self.defects = win_rj, nw, K, defects
        self.pair = win_rj.map(THREADS, "thread", THREADS) if nw >= THREADS else None
        block = win_rj.sparsity_out(1)
        m = block.size1()
        row = np.asarray(block.row(), dtype=np.int64)
        self._colind = col = np.asarray(block.colind(), dtype=np.int64)
        counts = np.diff(col)
        self.shape = (m * nw, K + (block.size2() - K) * nw)
        big = max(m * nw, int(col[-1]) * nw) >= np.iinfo(np.int32).max
        itype = np.int64 if big else np.int32
        off = (np.arange(nw, dtype=np.int64) * m)[:, None]
        # theta columns: every window's rows in turn; then each window's own columns
        parts = [(row[col[c] : col[c + 1]][None, :] + off).ravel() for c in range(K)]
        parts.append((row[col[K] :][None, :] + off).ravel())
        self._indices = np.concatenate(parts).astype(itype)
        sizes = np.r_[counts[:K] * nw, np.tile(counts[K:], nw)]
        self._indptr = np.r_[0, np.cumsum(sizes)].astype(itype)
        # where each input of the window function lives: (source, offset, entries per
        # window or None when shared); sources 0 v, 1 p_base, 2 S, 3 data
        nd = win_rj.size1_in(0)
        pieces, off = [], 0
        for a, b in shapes:
            pieces.append((off, a * b // nw if b % nw == 0 and b >= nw else None))
            off += a * b
        x0, U, dt, wt, W, Q, YW, *rest = pieces
        sigma = rest[-1]
        self._where = [
            (0, K, nd),
            (3, *x0),
            (3, *U),
            (3, *dt),
            (3, *wt),
            (3, *W),
            (3, *Q),
            (3, *YW),
            (1, 0, None),
            (2, 0, None),
            (0, 0, None),
            (3, sigma[0], None),
        ]
        if len(rest) == 2:  # the hand-over row selector of linked windows
            self._where.append((3, *rest[0]))  # fmt: skip

    def pattern(self) -> sp.csc_matrix:
        """The Jacobian's structure: a CSC matrix of ones."""
        ones = np.ones(self._indices.size)
        return sp.csc_matrix((ones, self._indices, self._indptr), shape=self.shape)

    def defect_sparsity(self) -> ca.Sparsity:
        """The structure of the defects' Jacobian (linked windows)."""
        return self.defects.sparsity_out(1)

    def matrix(self, blocks: np.ndarray) -> sp.csc_matrix:
        """The Jacobian (CSC) from the nonzeros of the window blocks, window after window."""
        B = np.asarray(blocks).reshape(self.nw, -1)
        col = self._colind
        parts = [B[:, col[c] : col[c + 1]].ravel() for c in range(self.K)]
        parts.append(B[:, col[self.K] :].ravel())
        return sp.csc_matrix(
            (np.concatenate(parts), self._indices, self._indptr), shape=self.shape, copy=False
        )

    def _windows(self, src: list) -> list:
        """Every output of the window function for all windows, window after window."""
        f = self.win_rj
        out = [np.empty(f.nnz_out(i) * self.nw) for i in range(f.n_out())]
        buffers: dict = {}
        # shared inputs (parameters, noise levels) once per mapped window
        shared = {
            i: src[s][off : off + f.nnz_in(i)]
            for i, (s, off, per) in enumerate(self._where)
            if per is None
        }
        for fn, j0, count in self._calls():
            if count not in buffers:
                tiled = {i: np.tile(a, count) for i, a in shared.items()}
                buffers[count] = (*function_buffer(fn), tiled)
            buf, run, tiled = buffers[count]
            for i, (s, off, per) in enumerate(self._where):
                if per is None:
                    piece = tiled[i]
                else:
                    piece = src[s][off + j0 * per : off + (j0 + count) * per]
                buf.set_arg(i, memoryview(piece))
            for i, o in enumerate(out):
                n = f.nnz_out(i)
                buf.set_res(i, memoryview(o[j0 * n : (j0 + count) * n]))
            run()
            if buf.ret() != 0:
                raise RuntimeError(f"{f.name()}: evaluation failed (return code {buf.ret()})")
        return out

    def _calls(self):
        """``(function, first window, windows)`` of each evaluation."""
        m = (self.nw // THREADS) * THREADS if self.pair is not None else 0
        for j0 in range(0, m, THREADS):
            yield self.pair, j0, THREADS
        for j0 in range(m, self.nw):
            yield self.win_rj, j0, 1

    def __call__(self, v, p_base, S, data) -> tuple:
        """``(r, J)``, and on linked windows ``(r, J, c, Jc)`` (``J``, ``Jc`` scipy CSC)."""
        src = [np.ascontiguousarray(np.asarray(a, dtype=float).reshape(-1, order="F"))
               for a in (v, p_base, S, data)]  # fmt: skip
        out = self._windows(src)
        J = self.matrix(out[1])
        if self.defects is None:
            return out[0], J
        c, Jc = evaluate(self.defects, out[2], out[3], *src)
        return out[0], J, c, csc_of(Jc, self.defects.sparsity_out(1))


#: Threads evaluating the windows side by side.
THREADS = 2


def map_windows(fn: ca.Function, nw: int, args: list) -> list:
    """``fn`` over ``nw`` windows (``args`` as :meth:`casadi.Function.map` takes them: a
    window's inputs side by side, or one for all), ``THREADS`` windows at a time.

    CasADi's threaded map keeps a work vector per window it maps, not per thread: for the
    Jacobian of an hour of 50 Hz pieces, 570 MB. A serial map of threaded maps of
    ``THREADS`` windows keeps ``THREADS`` (the remaining windows are one more call)."""
    if nw < 2 * THREADS:
        return fn.map(nw, "thread", THREADS).call(args)
    per = [fn.size2_in(i) for i in range(fn.n_in())]
    m = (nw // THREADS) * THREADS
    mapped = fn.map(THREADS, "thread", THREADS).map(m // THREADS, "serial")

    def part(a, w, lo, hi):
        whole = (lo, hi) == (0, nw)
        return a[:, lo * w : hi * w] if a.shape[1] == w * nw != w and not whole else a

    out = mapped.call([part(a, w, 0, m) for a, w in zip(args, per, strict=True)])
    if m == nw:
        return out
    rest = fn.map(nw - m, "thread", THREADS).call(
        [part(a, w, m, nw) for a, w in zip(args, per, strict=True)]
    )
    return [ca.horzcat(a, b) for a, b in zip(out, rest, strict=True)]


def _build_problem(model, L, nw, K, outputs, substeps, jit, link=False):
    """``fr, fj, fy`` of all windows: ``fr`` and ``fy`` CasADi Functions ``(v, p_base, S,
    data) -> `` the residual (and with ``link`` the continuity defects of every consecutive
    pair of windows), the outputs; ``fj`` the :class:`WindowJacobian` (the same and their
    Jacobians in ``v = [theta; vec(delta)]``, NumPy and scipy CSC)."""
    win_r, win_rj, win_y = _window_functions(model, L, K, outputs, substeps, jit, link)
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    v = ca.MX.sym("v", K + nd * nw)
    pb = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    shapes = _data_shapes(model, L, nw, n_rate, link)
    data = ca.MX.sym("data", sum(a * b for a, b in shapes))
    pieces, i = [], 0
    for a, b in shapes:
        pieces.append(ca.reshape(data[i : i + a * b], a, b))
        i += a * b
    th, D = v[:K], ca.reshape(v[K:], nd, nw)
    args = [D, *pieces[:7], pb, S, th, pieces[-1], *(pieces[7:8] if link else [])]
    out_r = map_windows(win_r, nw, args)
    R = out_r[0]
    Y = map_windows(win_y, nw, [D, pieces[0], pieces[1], pieces[2], pb, S, th])[0]
    defects = None
    if link:
        # the defects and their Jacobian from every window's end state and its Jacobian
        XE = ca.MX.sym("x_end", model.nx, nw)
        DX = ca.MX.sym("dx_end", ca.repmat(win_rj.sparsity_out(3), 1, nw))
        if nw > 1:
            lf = _link_function(model, K, outputs).map(nw - 1)
            sig = ca.repmat(pieces[-1], 1, nw - 1)
            C = ca.vec(lf(out_r[1][:, :-1], ca.DM.zeros(model.nx, (K + nd) * (nw - 1)),
                          D[:, 1:], pieces[0][:, 1:], sig)[0])  # fmt: skip
            Cj, A, B = lf(XE[:, :-1], DX[:, : (K + nd) * (nw - 1)], D[:, 1:],
                          pieces[0][:, 1:], sig)  # fmt: skip
            m = nd * (nw - 1)
            a_blocks = [A[:, j * (K + nd) : (j + 1) * (K + nd)] for j in range(nw - 1)]
            b_blocks = [B[:, j * nd : (j + 1) * nd] for j in range(nw - 1)]
            JC_th = ca.vertcat(*[blk[:, :K] for blk in a_blocks]) if K else ca.MX(m, 0)
            JC_d = ca.horzcat(ca.diagcat(*[blk[:, K:] for blk in a_blocks]), ca.MX(m, nd))
            JC_d = JC_d + ca.horzcat(ca.MX(m, nd), ca.diagcat(*b_blocks))
            JC = ca.horzcat(JC_th, JC_d)
            fr = ca.Function("r", [v, pb, S, data], [ca.vec(R), C])
            outs = [ca.vec(Cj), JC]
        else:  # one window: nothing to join
            fr = ca.Function("r", [v, pb, S, data], [ca.vec(R), ca.MX(0, 1)])
            outs = [ca.MX(0, 1), ca.MX(0, v.shape[0])]
        defects = ca.Function("defects", [XE, DX, v, pb, S, data], outs)
    else:
        fr = ca.Function("r", [v, pb, S, data], [ca.vec(R)])
    fy = ca.Function("y", [v, pb, S, data], [Y])
    return fr, WindowJacobian(win_rj, nw, K, shapes, defects), fy


def _problem_solver(model, L, nw, K, outputs, substeps, jit, max_iter=IPOPT_MAX_ITER):
    """``(solver, keep)``: the IPOPT solver and the Python objects it calls (kept alive)."""
    key = ("solver", structure_key(model), L, nw, K, outputs, substeps, jit, max_iter)
    return _cached(key, lambda: _build_solver(model, L, nw, K, outputs, substeps, jit, max_iter))


_PATTERNS: OrderedDict = OrderedDict()


def _pattern_of(spy: ca.Sparsity) -> tuple:
    """``(row, colind)`` of a CasADi sparsity as int64 arrays, converted once per pattern."""
    key = (spy.hash(), spy.size1(), spy.size2(), spy.nnz())
    pat = _PATTERNS.get(key)
    if pat is None:
        pat = (np.asarray(spy.row(), dtype=np.int64), np.asarray(spy.colind(), dtype=np.int64))
        _PATTERNS[key] = pat
        while len(_PATTERNS) > CACHE_SIZE:
            _PATTERNS.popitem(last=False)
    return pat


def to_csc(J: ca.DM) -> sp.csc_matrix:
    """A CasADi sparse matrix as scipy CSC, its (constant) pattern converted once."""
    return csc_of(np.asarray(J.nonzeros(), dtype=float), J.sparsity())


def csc_of(nz: np.ndarray, spy: ca.Sparsity) -> sp.csc_matrix:
    """The nonzeros ``nz`` (CasADi's column-major order) of a matrix of sparsity ``spy`` as
    scipy CSC, sharing ``nz`` (no copy)."""
    row, colind = _pattern_of(spy)
    return sp.csc_matrix((nz, row, colind), shape=(spy.size1(), spy.size2()), copy=False)


def scale_columns(J: sp.csc_matrix, scale: np.ndarray) -> sp.csc_matrix:
    """``J @ diag(scale)`` for a CSC ``J``, in place (each column times its factor: the
    same numbers as the product, without a copy of ``J``)."""
    J.data *= np.repeat(np.asarray(scale, dtype=float), np.diff(J.indptr))
    return J


def vstack_csc(A: sp.csc_matrix, B: sp.csc_matrix) -> sp.csc_matrix:
    """``[A; B]`` as CSC for a small ``B`` (each column: ``A``'s entries, then ``B``'s): the
    entries of ``B`` inserted into ``A``'s arrays, without scipy's detour through COO and a
    sort of every entry (a few hundred MB and most of a second on an hour of samples)."""
    A, B = sp.csc_matrix(A), sp.csc_matrix(B)
    if A.shape[1] != B.shape[1]:  # pragma: no cover - programming error
        raise ValueError("vstack_csc: the matrices have different numbers of columns")
    A.sort_indices()
    B.sort_indices()
    col = np.repeat(np.arange(B.shape[1]), np.diff(B.indptr))
    at = A.indptr[col + 1]
    data = np.insert(A.data, at, B.data)
    indices = np.insert(A.indices.astype(np.int64), at, B.indices.astype(np.int64) + A.shape[0])
    return sp.csc_matrix(
        (data, indices, A.indptr.astype(np.int64) + B.indptr),
        shape=(A.shape[0] + B.shape[0], A.shape[1]),
    )


def function_buffer(fn: ca.Function):
    """``fn.buffer()`` made once per Function and thread, then reused.

    Making a buffer allocates the Function's work vectors: for a window Jacobian of 50 Hz
    pieces about 10 ms, as much as a residual evaluation, and IPOPT's line search evaluates
    thousands of times per search. The caller sets every argument and result pointer
    before each run, so a reused buffer holds nothing of the last call.
    """
    cache = getattr(fn, "_airbearing_buffers", None)
    if cache is None:
        cache = {}
        try:
            fn._airbearing_buffers = cache
        except AttributeError:  # pragma: no cover - a Function that takes no attribute
            return fn.buffer()
    key = threading.get_ident()
    if key not in cache:
        cache[key] = fn.buffer()
    return cache[key]


def evaluate(fn: ca.Function, *args) -> list:
    """The nonzeros of every output of ``fn(*args)``, written by CasADi straight into new
    NumPy arrays (:meth:`casadi.Function.buffer`).

    A call through ``fn(...)`` converts every input to a DM and every output back, element
    by element through Python lists: on an hour of samples that costs several times the
    compiled evaluation itself and a transient Python list of every Jacobian entry (32 bytes
    each). Same values as the call.

    Parameters
    ----------
    fn : casadi.Function
        Dense inputs.
    *args : array-like
        One per input, its entries in column-major (Fortran) order.

    Returns
    -------
    list of ndarray
        Per output, its nonzeros in CasADi's column-major order (:func:`csc_of` makes a
        sparse one a matrix).
    """
    buf, run = function_buffer(fn)
    keep = []
    for i, a in enumerate(args):
        x = np.ascontiguousarray(np.asarray(a, dtype=float).reshape(-1, order="F"))
        if x.size != fn.nnz_in(i):  # pragma: no cover - programming error
            raise ValueError(f"{fn.name()}: input {i} has {x.size} entries, not {fn.nnz_in(i)}")
        keep.append(x)
        buf.set_arg(i, memoryview(x))
    out = [np.empty(fn.nnz_out(i)) for i in range(fn.n_out())]
    for i, o in enumerate(out):
        buf.set_res(i, memoryview(o))
    run()
    if buf.ret() != 0:
        raise RuntimeError(f"{fn.name()}: evaluation failed (return code {buf.ret()})")
    return out


class _Oracle:
    """The weighted residual ``r`` and its Jacobian at the last point, shared by IPOPT's
    objective, gradient and Gauss-Newton Hessian: one compiled evaluation per iterate."""

    def __init__(self, fr, fj, n_p: int, K: int, n_v: int) -> None:
        self.fr, self.fj = fr, fj
        self.n_p, self.K, self.n_v = n_p, K, n_v
        self.z = self.par = self.r = self.J = self.cur = None

    def set(self, par: np.ndarray) -> None:
        """The solver parameters of the next solve (kept here, not passed through IPOPT:
        converting the log's data vector on every callback would cost more than the fit)."""
        self.cur, self.z = par, None

    def _args(self, z, par):
        n_p, K, n_v = self.n_p, self.K, self.n_v
        pb = par[:n_p]
        S = par[n_p : n_p + n_p * K].reshape(n_p, K, order="F")
        scale = par[n_p + n_p * K : n_p + n_p * K + n_v]
        return z * scale, pb, S, par[n_p + n_p * K + n_v :], scale

    def _same(self, z, par) -> bool:
        return self.z is not None and par is self.par and np.array_equal(z, self.z)

    def release(self) -> None:
        """Forget the last iterate (its Jacobian is large on long logs; the cached solver
        keeps this oracle)."""
        self.z = self.r = self.J = None
        if hasattr(self, "Jc"):
            self.c = self.Jc = None

    def r_at(self, z, par) -> np.ndarray:
        if not self._same(z, par):
            v, pb, S, data, _ = self._args(z, par)
            self.z, self.par, self.J = z.copy(), par, None
            self.r = evaluate(self.fr, v, pb, S, data)[0]
        return self.r

    def rj_at(self, z, par):
        if not (self._same(z, par) and self.J is not None):
            v, pb, S, data, scale = self._args(z, par)
            r, J = self.fj(v, pb, S, data)
            self.z, self.par = z.copy(), par
            self.r = r
            self.J = scale_columns(J, scale)  # scipy CSC (sparse windows)
        return self.r, self.J


class _Call(ca.Callback):
    """A CasADi Function evaluated in Python (optionally with a Jacobian Function)."""

    def __init__(self, name, sizes, out_sp, fn, jac=None) -> None:
        ca.Callback.__init__(self)
        self.sizes, self.out_sp, self.fn, self.jac = sizes, out_sp, fn, jac
        self.construct(name, {})

    def get_n_in(self):
        return len(self.sizes)

    def get_n_out(self):
        return len(self.out_sp)

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.sizes[i], 1)

    def get_sparsity_out(self, i):
        return self.out_sp[i]

    def eval(self, arg):
        # DM.full() converts in C; np.asarray(DM) goes element by element
        return self.fn(*[a.full().ravel() for a in arg])

    def has_jacobian(self):
        return self.jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        return self.jac(name)


def ipopt_options(max_iter: int, objective_stop: bool = False) -> dict:
    """The IPOPT options every fit of the engine shares (quiet, scaled tolerances).

    ``objective_stop``: also stop when the objective has converged (``OBJECTIVE_STOP``),
    for warm-started fits near their optimum only (the process-noise descent): far from it
    a creeping IPOPT meets the same test.
    """
    return {
        # a trial point whose replay is not finite is IPOPT's to reject; CasADi's "NaN
        # detected" lines would only reach a notebook's output
        "show_eval_warnings": False,
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.max_iter": int(max_iter),
        "ipopt.tol": IPOPT_TOL,
        "ipopt.acceptable_tol": 1e-5,
        "ipopt.acceptable_iter": 3,
        "ipopt.mu_strategy": "adaptive",
        **(OBJECTIVE_STOP if objective_stop else {}),
    }


def _build_solver(model, L, nw, K, outputs, substeps, jit, max_iter=IPOPT_MAX_ITER):
    """IPOPT on ``z = v / scale``: objective 0.5 |r|^2, gradient J^T r, Hessian J^T J.

    Gauss-Newton: no second derivatives through the rollout. The objective, its gradient
    and the Hessian come from one compiled evaluation of ``(r, J)`` per iterate (a shared
    :class:`_Oracle`; trial points of the line search evaluate ``r`` alone). The
    objective's derivative in the solver parameters is declared structurally zero: IPOPT
    never uses it (no multipliers of the parameters are computed).
    """
    fr, fj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit)
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    n_p = model.n_p
    n_par = 0  # the solver parameters live in the oracle (:meth:`_Oracle.set`)
    o = _Oracle(fr, fj, n_p, K, n_v)

    def f(z, _par):
        r = o.r_at(z, o.cur)
        return [0.5 * float(r @ r)]

    def grad(z, _par):
        r, J = o.rj_at(z, o.cur)
        return [0.5 * float(r @ r), np.asarray(J.T @ r).ravel()]

    def jac_f(name):
        def fn(z, _par, _out):
            r, J = o.rj_at(z, o.cur)
            return [np.asarray(J.T @ r).reshape(1, -1), np.zeros((1, 0))]

        return _Call(name, [n_v, n_par, 1], [ca.Sparsity.dense(1, n_v), ca.Sparsity(1, n_par)], fn)

    def hess(z, _par, lam_f, _lam_g):
        _, J = o.rj_at(z, o.cur)
        return [np.triu(lam_f[0] * (J.T @ J).toarray())]

    F = _Call("nlp_f_cb", [n_v, n_par], [ca.Sparsity.dense(1, 1)], f, jac_f)
    G = _Call(
        "nlp_grad_f", [n_v, n_par], [ca.Sparsity.dense(1, 1), ca.Sparsity.dense(n_v, 1)], grad
    )
    H = _Call("nlp_hess_l", [n_v, n_par, 1, 0], [ca.Sparsity.upper(n_v)], hess)
    z = ca.MX.sym("z", n_v)
    par = ca.MX.sym("par", n_par)
    solver = ca.nlpsol(
        "output_error",
        "ipopt",
        {"x": z, "p": par, "f": F(z, par)},
        {
            "grad_f": G,
            "hess_lag": H,
            "calc_lam_p": False,
            "calc_lam_x": False,
            "calc_multipliers": False,
            **ipopt_options(max_iter),
        },
    )
    return solver, (F, G, H, o)
