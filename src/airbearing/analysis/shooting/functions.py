"""Compiled functions of the shooting engine: one window, all windows, the IPOPT solver.

One bounded cache (``CACHE_SIZE`` entries) keyed by the Model's STRUCTURE (a hash of
its serialized expressions, :func:`structure_key`), the window length, the number of
parameter slots and the output groups; the window functions are compiled to C through
the on-disk cache of :mod:`airbearing.models.compiled` (a new process loads them).
"""

from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict

import casadi as ca

from airbearing.models import quaternion as quat
from airbearing.models.model import Model

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
#: Relative eigenvalue of the reduced Fisher matrix below which a parameter is not identifiable.
FISHER_RCOND = 1e-10
#: Largest number of compiled function sets kept per process.
CACHE_SIZE = 48
#: Output groups a window can compare.
OUTPUTS = ("rate", "quat", "yaw")

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


_KEYS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def structure_key(model: Model) -> str:
    """A hash of the Model's expressions (dynamics, measurement, lag): equal for equal structure."""
    if model in _KEYS:
        return _KEYS[model]
    h = hashlib.sha1()
    for fn in (model.f, model.h, model._lag):
        h.update(fn.serialize().encode())
    h.update(repr((model.x_names, model.u_names, model.p_names, model.y_names)).encode())
    _KEYS[model] = key = h.hexdigest()
    return key


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


def _window_functions(model: Model, L: int, K: int, outputs: tuple, substeps: int, jit):
    key = ("window", structure_key(model), L, K, outputs, substeps, jit)
    return _cached(key, lambda: _build_window(model, L, K, outputs, substeps, jit))


def _build_window(model: Model, L: int, K: int, outputs: tuple, substeps: int, jit):
    dof = model.dof
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    nx_plant = model.nx - n_lag
    na = n_rate
    d = ca.SX.sym("delta", nd)
    xm = ca.SX.sym("x_meas", nx_plant)
    if dof == 3:
        rate0 = xm[4:7] + d[3:6]
        parts = [quat.qmul(xm[0:4], quat.qexp(d[0:3])), rate0, xm[7:]]
    else:
        yaw0 = xm[0] + d[0] if n_att else xm[0]
        rate0 = xm[1] + d[n_att]
        parts = [yaw0, rate0, xm[2:]]
    if n_lag:
        # the lagged gyro starts near the start rate, free per window
        parts.append(rate0 + d[n_att + n_rate :])
    x0_fn = ca.Function("x0", [d, xm], [ca.vertcat(*parts)])
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
    win_r = ca.Function("window_r", ins, [r], names, ["r"])
    win_rj = ca.Function(
        "window_rj", ins, [r, ca.jacobian(r, ca.vertcat(TH, D))], names, ["r", "J"]
    )
    win_y = ca.Function("window_y", [D, XM, U, DT, PB, S, TH], [Y])
    # the residual, its Jacobian and the outputs compiled to C as whole windows (the
    # derivatives are inside), cached on disk: a new process loads them
    return compiled(win_r, jit=jit), compiled(win_rj, jit=jit), compiled(win_y, jit=jit)


def _data_shapes(model: Model, L: int, nw: int, na: int) -> list:
    nx_plant = model.nx - len(model.lag_index)
    return [
        (nx_plant, nw),
        (model.nu, L * nw),
        (1, (L - 1) * nw),
        (1, L * nw),
        (na, L * nw),
        (4, L * nw),
        (1, L * nw),
        (2, 1),
    ]


def _problem_functions(model, L, nw, K, outputs, substeps, jit):
    key = ("problem", structure_key(model), L, nw, K, outputs, substeps, jit)
    return _cached(key, lambda: _build_problem(model, L, nw, K, outputs, substeps, jit))


def _build_problem(model, L, nw, K, outputs, substeps, jit):
    win_r, win_rj, win_y = _window_functions(model, L, K, outputs, substeps, jit)
    n_att, n_rate, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_lag
    v = ca.MX.sym("v", K + nd * nw)
    pb = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    shapes = _data_shapes(model, L, nw, n_rate)
    data = ca.MX.sym("data", sum(a * b for a, b in shapes))
    pieces, i = [], 0
    for a, b in shapes:
        pieces.append(ca.reshape(data[i : i + a * b], a, b))
        i += a * b
    th, D = v[:K], ca.reshape(v[K:], nd, nw)
    args = [D, *pieces[:7], pb, S, th, pieces[7]]
    R = win_r.map(nw, "thread", 2)(*args)
    Rj, Jj = win_rj.map(nw, "thread", 2)(*args)
    n = Rj.shape[0]
    blocks = [Jj[:, j * (K + nd) : (j + 1) * (K + nd)] for j in range(nw)]
    J_th = ca.vertcat(*[blk[:, :K] for blk in blocks]) if K else ca.MX(n * nw, 0)
    J = ca.horzcat(J_th, ca.diagcat(*[blk[:, K:] for blk in blocks]))
    Y = win_y.map(nw, "thread", 2)(D, pieces[0], pieces[1], pieces[2], pb, S, th)
    fr = ca.Function("r", [v, pb, S, data], [ca.vec(R)])
    fj = ca.Function("rj", [v, pb, S, data], [ca.vec(Rj), J])
    fy = ca.Function("y", [v, pb, S, data], [Y])
    return fr, fj, fy


def _problem_solver(model, L, nw, K, outputs, substeps, jit):
    key = ("solver", structure_key(model), L, nw, K, outputs, substeps, jit)
    return _cached(key, lambda: _build_solver(model, L, nw, K, outputs, substeps, jit))


def _build_solver(model, L, nw, K, outputs, substeps, jit):
    """IPOPT on ``z = v / scale``: objective 0.5 |r|^2, gradient J^T r, Hessian J^T J."""
    fr, fj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit)
    fr_plain = _problem_functions(model, L, nw, K, outputs, substeps, False)[0]
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    n_p = model.n_p
    n_data = fr.size1_in(3)
    z = ca.MX.sym("z", n_v)
    par = ca.MX.sym("par", n_p + n_p * K + n_v + n_data)
    pb, S = par[:n_p], ca.reshape(par[n_p : n_p + n_p * K], n_p, K)
    scale = par[n_p + n_p * K : n_p + n_p * K + n_v]
    data = par[n_p + n_p * K + n_v :]
    rz, Jv = fj(z * scale, pb, S, data)
    Jz = Jv * ca.repmat(scale.T, Jv.shape[0], 1)
    lam = ca.MX.sym("lam_f")
    grad_f = ca.Function(
        "nlp_grad_f",
        [z, par],
        [0.5 * ca.sumsqr(rz), ca.mtimes(Jz.T, rz)],
        ["x", "p"],
        ["f", "grad"],
    )
    hess = ca.Function(
        "nlp_hess_l",
        [z, par, lam, ca.MX.sym("lam_g", 0)],
        [ca.triu(lam * ca.mtimes(Jz.T, Jz))],
        ["x", "p", "lam_f", "lam_g"],
        ["triu_hess_gamma_x_x"],
    )
    return ca.nlpsol(
        "output_error",
        "ipopt",
        # the objective itself through the uncompiled (differentiable) residual: IPOPT's set-up
        # differentiates it once; every iteration uses the compiled gradient and Hessian
        {"x": z, "p": par, "f": 0.5 * ca.sumsqr(fr_plain(z * scale, pb, S, data))},
        {
            "grad_f": grad_f,
            "hess_lag": hess,
            "calc_lam_p": False,
            "calc_lam_x": False,
            "calc_multipliers": False,
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.max_iter": IPOPT_MAX_ITER,
            "ipopt.tol": IPOPT_TOL,
            "ipopt.acceptable_tol": 1e-5,
            "ipopt.acceptable_iter": 3,
            "ipopt.mu_strategy": "adaptive",
        },
    )
