"""The one multiple-shooting output-error engine (replay, discrepancy, identification).

A log is cut into windows of ``L`` rows that never span a gap. Window ``j``
restarts from an estimate of the state at its first row, ``x_meas_j``,
corrected by a small perturbation ``delta_j`` (a rotation vector on the
attitude for dof 3, an offset on the yaw when the yaw is fitted, an offset on
each rate, and on each lagged rate of a ``sensor_lag``). The Model is rolled
over the window sample to sample with the LOGGED intervals (``dt`` is an input
of every step, so jittered times are integrated as logged) and its measurement
is compared with the logged one:

- ``rate``: the measured angular rate (a gyro), residual ``(w_meas - w_model) / sigma_rate``;
- ``quat``: the attitude quaternion, residual ``2 vec(conj(q_model) (x) q_meas) / sigma_att``
  (the small rotation, rad, that takes the model attitude to the measured one);
- ``yaw``: the yaw of a dof-1 platform, residual ``(yaw_meas - yaw_model) / sigma_att``.

Each residual is multiplied by the row's weight ``m`` (0 for an outlier row and
for the padding of a short window at the end of a segment, else 1), so a row
that is not usable enters no residual, no fit and no gap.

Free parameters enter as ``p = p_base + S theta`` with ``S`` an input, so ONE
compiled window function serves every choice of free parameters (up to
``THETA_SLOTS`` of them). Compiled functions are cached per process in one
bounded cache keyed by the Model's structure (its serialized expressions), not
by object identity: testbeds that differ only in parameter values share them.

Solver-status policy (stated once, here)
    ``converged``: IPOPT ``Solve_Succeeded``.
    ``warning``: ``Solved_To_Acceptable_Level`` (converged to the looser
    acceptable tolerance: the fit is used, the status is reported).
    ``error``: anything else (iteration limit, restoration failure, a non-finite
    replay): :class:`airbearing.errors.SolverError` is raised with the status.

Standard errors
    From the Gauss-Newton (Fisher) matrix ``F = J^T J`` of the weighted
    residual, the window initial states ELIMINATED (Schur complement of their
    block), scaled by the reduced chi-square. A parameter whose Jacobian column
    is zero (nothing excites it) or whose reduced Fisher matrix is singular
    (relative eigenvalue below ``FISHER_RCOND``: the log cannot tell it from the
    initial states or from another parameter) gets no number but a reason.
"""

from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from airbearing.errors import SolverError
from airbearing.models import quaternion as quat
from airbearing.models.model import Model

__all__ = [
    "DEFAULT_SUBSTEPS",
    "THETA_SLOTS",
    "Fit",
    "ShootingProblem",
    "WindowSet",
    "classify_status",
    "compiled",
    "jit_available",
    "step_function",
    "structure_key",
    "theta_errors",
]

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

_CONVERGED = ("Solve_Succeeded",)
_WARNING = ("Solved_To_Acceptable_Level",)


def classify_status(status: str) -> str:
    """IPOPT return status -> ``"converged"``, ``"warning"`` or ``"error"`` (module doc)."""
    if status in _CONVERGED:
        return "converged"
    if status in _WARNING:
        return "warning"
    return "error"


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


# ----------------------------------------------------------------------------
# window data


@dataclass(frozen=True, eq=False)
class WindowSet:
    """The data of ``n`` windows of ``L`` rows, ready for the compiled window function.

    Attributes
    ----------
    x0 : ndarray (n, nx_plant)
        State estimate at each window's first row (attitude, rate, gimbal angles).
    u : ndarray (n, L, nu)
        Inputs held over each row's interval.
    dt : ndarray (n, L - 1)
        Logged intervals, s (padding rows: a tiny positive interval, weight 0).
    weight : ndarray (n, L)
        1 for a usable row, 0 for an outlier or padding.
    rate : ndarray (n, L, na) or None
        Measured rates (output ``rate``), rad/s.
    quat : ndarray (n, L, 4) or None
        Measured attitude quaternion (output ``quat``).
    yaw : ndarray (n, L) or None
        Measured yaw (output ``yaw``), rad.
    rows : ndarray (n, L) of int
        The log row of each window sample (padding repeats the last row).
    source : ndarray (n,) of int
        Which log (or segment group) each window comes from.
    """

    x0: np.ndarray
    u: np.ndarray
    dt: np.ndarray
    weight: np.ndarray
    rate: np.ndarray | None
    quat: np.ndarray | None
    yaw: np.ndarray | None
    rows: np.ndarray
    source: np.ndarray

    @property
    def n(self) -> int:
        return self.x0.shape[0]

    @property
    def length(self) -> int:
        return self.weight.shape[1]

    def subset(self, which) -> WindowSet:
        """The windows at positions ``which``."""
        which = np.asarray(which, dtype=int)

        def pick(a):
            return None if a is None else a[which]

        return WindowSet(
            x0=self.x0[which],
            u=self.u[which],
            dt=self.dt[which],
            weight=self.weight[which],
            rate=pick(self.rate),
            quat=pick(self.quat),
            yaw=pick(self.yaw),
            rows=self.rows[which],
            source=self.source[which],
        )


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


# ----------------------------------------------------------------------------
# fits


@dataclass(frozen=True, eq=False)
class Fit:
    """One output-error fit of a :class:`ShootingProblem`.

    Attributes
    ----------
    theta : ndarray (k,)
        Fitted free parameters (SI units of the Model's parameters).
    theta_std : ndarray (k,)
        1-sigma (module doc); NaN where not identifiable.
    not_identifiable : tuple of str
        Per parameter: "" or the reason it cannot be identified from the data.
    p : ndarray
        The full parameter vector.
    delta : ndarray (n_delta, n_windows)
        Fitted initial-state perturbations.
    rss : float
        Weighted residual sum of squares.
    n_res : int
        Number of weighted residuals of usable rows.
    n_free : int
        Number of free variables (``k + delta.size``).
    gap : float
        RMS of the primary output's residual (rad/s for rates, rad for attitude).
    iterations : int
    status : str
        IPOPT status; ``level`` its class (:func:`classify_status`).
    cov : ndarray (k, k)
        Covariance of ``theta`` (NaN rows where not identifiable).
    """

    theta: np.ndarray
    theta_std: np.ndarray
    p: np.ndarray
    delta: np.ndarray
    rss: float
    n_res: int
    n_free: int
    gap: float
    iterations: int
    status: str = ""
    level: str = "converged"
    not_identifiable: tuple = ()
    cov: np.ndarray | None = None
    extra: dict = field(default_factory=dict)  # "r", "J" (scipy CSC, unscaled) at the fit


def theta_errors(J, k: int, s2: float, names=None):
    """Standard errors of the first ``k`` columns of ``J`` with the others eliminated.

    Parameters
    ----------
    J : scipy sparse or ndarray (n_res, n_free)
        Jacobian of the weighted residual at the fit.
    k : int
        Number of parameters (the leading columns); the rest are nuisance (initial states).
    s2 : float
        Residual variance factor (reduced chi-square).

    Returns
    -------
    std : ndarray (k,)
        1-sigma, NaN where not identifiable.
    cov : ndarray (k, k)
    reasons : tuple of str
        "" or why the parameter cannot be identified.
    """
    Jd = J.toarray() if hasattr(J, "toarray") else np.asarray(J)
    if k == 0:
        return np.zeros(0), np.zeros((0, 0)), ()
    col = np.linalg.norm(Jd, axis=0)
    reasons = ["" for _ in range(k)]
    for i in range(k):
        if not col[i] > 0:
            reasons[i] = "no usable sample is sensitive to it (nothing in the log excites it)"
    c = np.where(col > 0, col, 1.0)
    Js = Jd / c
    F = Js.T @ Js
    Ftt, Ftd, Fdd = F[:k, :k], F[:k, k:], F[k:, k:]
    if Fdd.size:
        Fr = Ftt - Ftd @ np.linalg.pinv(Fdd, rcond=1e-12, hermitian=True) @ Ftd.T
    else:
        Fr = Ftt
    Fr = 0.5 * (Fr + Fr.T)
    ev, V = np.linalg.eigh(Fr)
    ok = np.array([not r for r in reasons])
    good = ev > FISHER_RCOND * max(float(np.max(np.diag(Ftt))), 1e-300)
    for i in range(k):
        if reasons[i]:
            continue
        # parameter i loads on a (near) null direction of the reduced Fisher matrix
        load = np.abs(V[i, ~good])
        if load.size and float(np.max(load)) > 1e-3:
            reasons[i] = (
                "its effect on the output cannot be told from the windows' initial states "
                "or the other parameters (singular Fisher matrix)"
            )
            ok[i] = False
    cov_s = (V[:, good] / ev[good]) @ V[:, good].T * s2
    cov = cov_s / np.outer(c[:k], c[:k])
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    for i in range(k):
        if not ok[i] or not std[i] > 0:
            std[i] = np.nan
            cov[i, :] = cov[:, i] = np.nan
            if not reasons[i]:
                reasons[i] = "zero variance: not identifiable from this log"
    return std, cov, tuple(reasons)


class ShootingProblem:
    """The multiple-shooting output error of one Model on a :class:`WindowSet`.

    Parameters
    ----------
    model : Model
    windows : WindowSet
    outputs : tuple of str
        Output groups compared (``rate``, ``quat``, ``yaw``; module doc); the first is
        the primary one, whose RMS residual is the gap.
    sigma_rate, sigma_att : float
        Noise levels (rad/s, rad) that weight the residuals.
    substeps : int
        RK4 sub-steps per sample.
    jit : bool, optional
        Compile to C (default: when a compiler is available).
    theta_slots : int
        Fits with up to this many free parameters share one compiled Jacobian.

    Notes
    -----
    Residual layout: window after window; within a window each output group in the
    order of ``outputs``, sample-major.
    """

    def __init__(
        self,
        model: Model,
        windows: WindowSet,
        outputs: tuple,
        sigma_rate: float,
        sigma_att: float,
        *,
        substeps: int = DEFAULT_SUBSTEPS,
        jit: bool | None = None,
        theta_slots: int = THETA_SLOTS,
    ) -> None:
        for o in outputs:
            if o not in OUTPUTS:  # pragma: no cover - programming error
                raise ValueError(f"unknown output group {o!r}")
        self.model, self.windows, self.outputs = model, windows, tuple(outputs)
        self.substeps, self.jit, self.theta_slots = int(substeps), jit, int(theta_slots)
        self.sigma_rate, self.sigma_att = float(sigma_rate), float(sigma_att)
        self.n_att, self.n_rate, self.n_lag = delta_layout(model, self.outputs)
        self.n_delta = self.n_att + self.n_rate + self.n_lag
        nw, L = windows.n, windows.length
        sizes = {"rate": self.n_rate, "quat": 3, "yaw": 1}
        group = np.concatenate([np.full(sizes[o] * L, i) for i, o in enumerate(self.outputs)])
        wrow = np.concatenate([np.repeat(np.arange(L), sizes[o]) for o in self.outputs])
        self.n_win_res = group.size
        self.group = np.tile(group, nw)  # output group of each residual
        self.sample = np.tile(wrow, nw) + np.repeat(np.arange(nw) * L, group.size)
        self.usable = windows.weight.reshape(-1)[self.sample] > 0
        self.n_res = int(self.usable.sum())
        self.primary = self.group == 0
        self._data = self._data_vector()

    # ------------------------------------------------------------------ plumbing
    def _data_vector(self) -> np.ndarray:
        w = self.windows
        nw, L = w.n, w.length
        na = self.n_rate

        def cols(a, rows):  # (nw, L, rows) -> (rows, L nw)
            return np.zeros((rows, L * nw)) if a is None else a.reshape(nw * L, rows).T

        parts = (
            w.x0.T,
            w.u.reshape(nw * L, -1).T,
            w.dt.reshape(1, -1),
            w.weight.reshape(1, -1),
            cols(w.rate, na),
            cols(w.quat, 4),
            np.zeros((1, L * nw)) if w.yaw is None else w.yaw.reshape(1, -1),
            np.array([[max(self.sigma_rate, 1e-300)], [max(self.sigma_att, 1e-300)]]),
        )
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1, order="F") for a in parts])

    def _key(self, K: int) -> tuple:
        return (
            self.model,
            self.windows.length,
            self.windows.n,
            K,
            self.outputs,
            self.substeps,
            self.jit,
        )

    def _pad(self, S: np.ndarray):
        k = S.shape[1]
        K = max(self.theta_slots, k)
        return np.hstack([S, np.zeros((S.shape[0], K - k))]), K

    def _eval(self, which: int, v, p_base, S):
        return _problem_functions(*self._key(S.shape[1]))[which](v, p_base, S, self._data)

    def _v(self, delta, S, theta=None):
        Sp, K = self._pad(np.zeros((self.model.n_p, 0)) if S is None else S)
        k = 0 if S is None else S.shape[1]
        th = np.zeros(k) if theta is None else np.asarray(theta, dtype=float)
        d = np.asarray(delta, dtype=float).reshape(-1, order="F")
        return np.concatenate([th, np.zeros(K - k), d]), Sp

    # ------------------------------------------------------------------ evaluation
    def residual(self, delta: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Weighted residual at ``delta`` (n_delta, n_windows) and parameters ``p``."""
        v, Sp = self._v(delta, None)
        return np.asarray(self._eval(0, v, np.asarray(p, dtype=float), Sp)).ravel()

    def gap_of_residual(self, r: np.ndarray, mask: np.ndarray | None = None) -> float:
        """RMS of the primary output's residual over usable rows (its unit)."""
        sel = self.primary & self.usable
        if mask is not None:
            sel &= mask
        sigma = self.sigma_rate if self.outputs[0] == "rate" else self.sigma_att
        if not sel.any():
            return float("nan")
        return float(sigma * np.sqrt(np.mean(r[sel] ** 2)))

    def gap_of(self, delta: np.ndarray, p: np.ndarray) -> float:
        """RMS primary output error at ``delta``, ``p``."""
        return self.gap_of_residual(self.residual(delta, p))

    def outputs_at(self, delta: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Model measurement at every window sample: (n_windows, L, ny)."""
        v, Sp = self._v(delta, None)
        Y = np.asarray(self._eval(2, v, np.asarray(p, dtype=float), Sp))
        nw, L = self.windows.n, self.windows.length
        return Y.T.reshape(nw, L, -1)

    def jacobian(self, fit: Fit, S: np.ndarray | None = None):
        """Weighted residual ``r`` and its Jacobian (scipy CSC) in ``[theta; vec(delta)]``."""
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        k = S.shape[1]
        v, Sp = self._v(fit.delta, S, fit.theta)
        K = Sp.shape[1]
        p_base = fit.p - S @ fit.theta if k else fit.p
        r, J = self._eval(1, v, p_base, Sp)
        keep = np.r_[np.arange(k), np.arange(K, J.shape[1])]
        return np.asarray(r).ravel(), J.sparse().tocsc()[:, keep]

    def fit(
        self,
        p_base: np.ndarray,
        S: np.ndarray | None = None,
        theta0: np.ndarray | None = None,
        *,
        lower: np.ndarray | None = None,
        upper: np.ndarray | None = None,
        delta0: np.ndarray | None = None,
        name: str = "output error",
    ) -> Fit:
        """Fit the window initial states (and ``theta``) by IPOPT with a Gauss-Newton Hessian.

        Parameters
        ----------
        p_base : ndarray (n_p,)
            Parameters with every free entry at its base value.
        S : ndarray (n_p, k), optional
            ``p = p_base + S theta``; None fits the initial states only.
        theta0, lower, upper : ndarray (k,), optional
            Start and bounds of ``theta`` (default 0, unbounded).
        delta0 : ndarray (n_delta, n_windows), optional
            Start of the initial-state perturbations (default 0).
        name : str
            Names the problem in a SolverError.

        Raises
        ------
        SolverError
            When the status is an error (module doc) or the replay is not finite.
        """
        p_base = np.asarray(p_base, dtype=float)
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        k = S.shape[1]
        nd, nw = self.n_delta, self.windows.n
        d0 = np.zeros((nd, nw)) if delta0 is None else np.asarray(delta0, dtype=float)
        v0, Sp = self._v(d0, S, theta0)
        K = Sp.shape[1]
        lb = np.full(v0.size, -np.inf)
        ub = np.full(v0.size, np.inf)
        if lower is not None:
            lb[:k] = lower
        if upper is not None:
            ub[:k] = upper
        lb[k:K] = ub[k:K] = 0.0  # unused slots
        v0 = np.clip(v0, lb, ub)
        r0, J0 = self._eval(1, v0, p_base, Sp)
        r0 = np.asarray(r0).ravel()
        if not np.all(np.isfinite(r0)):
            raise SolverError(f"{name}: the replay is not finite at the starting point")
        col = np.sqrt(np.asarray(J0.sparse().power(2).sum(axis=0)).ravel())
        scale = np.where(col > 0, 1.0 / np.maximum(col, 1e-300), 1.0)
        solver = _problem_solver(*self._key(K))
        par = np.concatenate([p_base, Sp.reshape(-1, order="F"), scale, self._data])
        sol = solver(x0=v0 / scale, lbx=lb / scale, ubx=ub / scale, p=par)
        stats = solver.stats()
        status = str(stats.get("return_status", "?"))
        level = classify_status(status)
        if level == "error":
            raise SolverError(f"{name}: IPOPT did not converge ({status})")
        v = np.asarray(sol["x"]).ravel() * scale
        r, J = self._eval(1, v, p_base, Sp)
        r = np.asarray(r).ravel()
        if not np.all(np.isfinite(r)):
            raise SolverError(f"{name}: the fitted replay is not finite")
        keep = np.r_[np.arange(k), np.arange(K, v.size)]
        v = v[keep]
        J = J.sparse().tocsc()[:, keep]
        rss = float(r @ r)
        n_free = v.size
        theta = v[:k]
        s2 = rss / max(self.n_res - n_free, 1)
        std, cov, reasons = theta_errors(J, k, s2)
        p = p_base + S @ theta if k else p_base.copy()
        return Fit(
            theta=theta,
            theta_std=std,
            p=p,
            delta=v[k:].reshape(nd, nw, order="F"),
            rss=rss,
            n_res=self.n_res,
            n_free=n_free,
            gap=self.gap_of_residual(r),
            iterations=int(stats.get("iter_count", 0)),
            status=status,
            level=level,
            not_identifiable=reasons,
            cov=cov,
            extra={"r": r, "J": J},
        )
