"""Replay: a testbed's Model driven by a log's own measured inputs, and the gap to the data.

The Model of a testbed (:func:`airbearing.models.model.build_model`) is driven by
the inputs the log recorded -- slider positions, commanded dipoles and the cage
field for a platform; the commanded gimbal rates for a CMG cluster -- and its
measured angular rate is compared with the logged one.

Inputs (zero-order hold over each sample, FORMATS.md)
    platform: ``s1..s3`` from the log; ``mx..mz`` from the log (zero when absent);
    the cage field in the LAB frame, ``b_lab = R(q_meas) b_body`` from the log's
    ``bx, by, bz`` (FORMATS.md: the logged field is in body axes at the sample
    instant) -- its mean when the samples scatter by less than
    ``FIELD_CONSTANT_RTOL`` of its size (a held field seen through the attitude
    noise) -- or, when the log has no field, the testbed's ``[field] lab``.
    cmg: ``dd1..dd4`` from the log, the commanded rates applied from ``t_k``
    on; when the log has none, the forward difference of the measured gimbal
    angles ``(d_{k+1} - d_k) / dt``.

Multiple shooting
    The log is cut into ``n_w`` consecutive windows of ``L`` samples (the last
    ``N mod L`` samples are not used). Each window restarts from the measured
    state at its first sample ``s_j`` -- attitude (quaternion, or yaw for
    dof 1), rate and gimbal angles -- corrected by a small perturbation
    ``delta_j`` (a rotation vector on the attitude for dof 3, an offset on each
    rate, and on the lagged rate when the model has a ``sensor_lag``). The
    gimbal angles and the dof-1 yaw are taken as measured. ``delta_j`` is
    chosen to minimise the window's weighted output error (rates divided by the
    rate noise floor, plus, for dof 3, the attitude error divided by the
    attitude noise) with the model parameters held: so the comparison is not
    swamped by one noisy initial sample, nor by the divergence of a sensitive
    (pendulous, spinning) motion over a long horizon.

The gap (rad/s)
    ``gap = sqrt( sum_j sum_{i=0}^{L-1} sum_a (w_meas[s_j+i, a] - w_model_j[i, a])^2
    / (n_w * L * n_a) )``: the RMS over every used sample ``s_j + i`` of every
    window ``j`` and every free rate axis ``a`` (``wx, wy, wz`` for dof 3, ``wz``
    for dof 1) of the logged rate minus the Model's measured rate (gyro bias and
    sensor lag included when the Model has them), the window started from its
    fitted initial state. For a correct model it approaches the noise floor
    times ``sqrt(1 - n_free / n_res)``.

The noise floor (rad/s)
    Estimated from the data alone, without any model: the fourth difference
    of each logged rate axis, ``D4 w_k = w_{k+2} - 4 w_{k+1} + 6 w_k - 4 w_{k-1} + w_{k-2}``,
    removes a smooth motion (its size is ``(w dt)^4`` times the rate) and
    multiplies white noise of standard deviation ``sigma`` by ``sqrt(70)``; a
    median absolute deviation (times 1.4826) makes it robust to the few
    samples where the motion changes abruptly. The floor is the RMS over axes.
    The attitude noise of a dof-3 log is estimated alike from the body-frame
    attitude increments minus the trapezoidal integral of the logged rate.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from airbearing.errors import InputError, SolverError
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed
from airbearing.models import quaternion as quat
from airbearing.models.model import Model, build_model

__all__ = [
    "DEFAULT_WINDOW_S",
    "MIN_WINDOWS",
    "MIN_WINDOW_SAMPLES",
    "Fit",
    "NoiseFloor",
    "ReplayData",
    "ReplayProblem",
    "Windows",
    "compiled_step",
    "jit_available",
    "make_windows",
    "model_for",
    "noise_floor",
    "open_loop",
    "replay",
    "replay_data",
]

#: s, longest multiple-shooting window by default (shorter logs get at least 4 windows).
DEFAULT_WINDOW_S = 10.0
#: Fewest windows a log must give (the held-out test needs two halves).
MIN_WINDOWS = 2
#: Fewest samples in a window.
MIN_WINDOW_SAMPLES = 10
#: Order of the difference that removes the smooth motion in :func:`noise_floor`.
NOISE_DIFF_ORDER = 4
#: A lab field whose samples scatter less than this fraction of its size is taken as constant
#: (the scatter of a held cage field seen through an attitude noise of ~1e-3 rad is ~1e-3).
FIELD_CONSTANT_RTOL = 0.02
#: 1 / Phi^-1(3/4): median absolute deviation -> standard deviation of a normal law.
MAD_TO_SIGMA = 1.482602218505602
#: rad/s and rad: smallest noise level used as a weight (a noise-free log stays well scaled).
RATE_SIGMA_MIN = 1e-7
ATTITUDE_SIGMA_MIN = 1e-5
#: RK4 sub-steps per sample of a replay: on the seed-004 free oscillation (rates to 1.5 rad/s,
#: 20 Hz) 2 sub-steps differ from 4 by 7e-7 rad/s RMS over 10 s, 1e-3 of a gyro's noise.
DEFAULT_SUBSTEPS = 2
#: Free-parameter slots of a fit: unused slots are fixed at zero, so every fit with up to
#: this many parameters shares one compiled Jacobian (one number of AD directions).
THETA_SLOTS = 6
#: IPOPT iteration limit of an output-error fit (Gauss-Newton converges in a few).
IPOPT_MAX_ITER = 50
#: IPOPT convergence tolerance (scaled variables: a step of 1 moves the residual by ~1 sigma).
IPOPT_TOL = 1e-6
#: IPOPT statuses accepted as a converged fit.
_IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


# ----------------------------------------------------------------------------
# the log as Model inputs and measured states


@dataclass(frozen=True, eq=False)
class ReplayData:
    """A log turned into the inputs and measured states of a testbed's Model.

    Attributes
    ----------
    testbed : Testbed
    log : Log
        The log, validated against ``testbed``.
    t : ndarray (N,)
        Sample times, s.
    dt : float
        Sample period of the testbed, s.
    u : ndarray (N, nu)
        Inputs held over ``[t_k, t_k + dt)`` in the Model's ``u_names`` (SI).
    x : ndarray (N, nx)
        Measured plant state at each sample in the Model's plant ``x_names``
        (quaternion with its sign kept continuous, or yaw; rates; gimbal angles).
    w : ndarray (N, n_axes)
        Measured angular rate, rad/s, body axes.
    rate_names : tuple of str
        ``("wx", "wy", "wz")`` (dof 3) or ``("wz",)`` (dof 1).
    q : ndarray (N, 4) or None
        Measured attitude quaternion (dof 3), sign continuous.
    u_names, x_names : tuple of str
    notes : tuple of str
        How the inputs were obtained (field source, gimbal-rate source).
    """

    testbed: Testbed
    log: Log
    t: np.ndarray
    dt: float
    u: np.ndarray
    x: np.ndarray
    w: np.ndarray
    rate_names: tuple
    q: np.ndarray | None
    u_names: tuple
    x_names: tuple
    notes: tuple = ()

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self.t)

    @property
    def n_axes(self) -> int:
        """Number of free rate axes (3 or 1)."""
        return len(self.rate_names)

    def input(self, name: str) -> np.ndarray:
        """One input column by Model name, shape (N,)."""
        return self.u[:, self.u_names.index(name)]

    def state(self, name: str) -> np.ndarray:
        """One measured state column by Model name, shape (N,)."""
        return self.x[:, self.x_names.index(name)]


def replay_data(testbed: Testbed, log: Log) -> ReplayData:
    """Turn ``log`` into the inputs and measured states of ``testbed``'s Model.

    Parameters
    ----------
    testbed : Testbed
        The nominal testbed the log is compared with.
    log : Log
        A run of that testbed (FORMATS.md columns, SI units).

    Returns
    -------
    ReplayData

    Raises
    ------
    InputError
        If the log's columns do not fit the testbed's kind and dof (missing
        sliders, gimbal angles, rates or attitude) or its sampling differs from
        ``sensors.rate``; the message names the log and the column.
    """
    if not isinstance(testbed, Testbed):
        raise InputError(f"replay: expected a Testbed, got {type(testbed).__name__}")
    if not isinstance(log, Log):
        raise InputError(f"replay: expected a Log, got {type(log).__name__}")
    # validate the columns and the sampling against THIS testbed (kind, dof, rate)
    log = Log(log.data, log.source, testbed)
    model = build_model(testbed.replace(effects={}))
    n = log.n
    dof = testbed.body.dof
    notes = []
    rate_names = ("wx", "wy", "wz") if dof == 3 else ("wz",)
    w = log.columns(list(rate_names))
    if dof == 3:
        q = quat.continuous_branch(quat.normalize(log.quaternions()))
        x_att = q
        q_att = q
    else:
        yaw = log.yaw()
        if yaw is None:
            yaw = np.unwrap(quat.yaw_of(log.quaternions()))
        x_att = yaw[:, None]
        q_att = quat.from_yaw(yaw)
        q = None
    u = np.zeros((n, model.nu))
    ui = {name: i for i, name in enumerate(model.u_names)}
    cols = [x_att, w]
    if testbed.kind == "platform":
        u[:, [ui["s1"], ui["s2"], ui["s3"]]] = log.sliders()
        dip = log.dipoles()
        if dip is not None:
            u[:, [ui["mx"], ui["my"], ui["mz"]]] = dip
        b_body = log.fields()
        b_idx = [ui["bx_lab"], ui["by_lab"], ui["bz_lab"]]
        if b_body is not None:
            # FORMATS.md: bx, by, bz are the lab-held cage field in body axes at t_k
            b_lab = quat.rotate(q_att, b_body)
            mean = b_lab.mean(axis=0)
            spread = float(np.sqrt(np.mean(np.sum((b_lab - mean) ** 2, axis=1))))
            if spread <= FIELD_CONSTANT_RTOL * float(np.linalg.norm(mean)):
                # a constant cage field seen through a noisy attitude: its mean
                u[:, b_idx] = mean
                notes.append("cage field: the mean of the log's bx, by, bz rotated to the lab")
            else:
                u[:, b_idx] = b_lab
                notes.append("cage field: the log's bx, by, bz rotated to the lab frame")
        elif testbed.field is not None:
            u[:, b_idx] = testbed.field.lab_vec
            notes.append("cage field: the testbed's [field] lab (the log has no bx, by, bz)")
    else:
        d = log.gimbals()
        dd = log.gimbal_rates()
        if dd is None:
            dd = np.vstack([np.diff(d, axis=0) / log.dt, np.zeros((1, 4))])
            dd[-1] = dd[-2]
            notes.append("gimbal rates: forward differences of the measured angles")
        else:
            notes.append("gimbal rates: the log's commanded dd1..dd4, applied from t_k")
        u[:, [ui[f"dd{i}"] for i in range(1, 5)]] = dd
        cols.append(d)
    x = np.hstack(cols)
    if x.shape[1] != model.nx:  # pragma: no cover - guards the Model's state layout
        raise InputError(f"replay: measured state has {x.shape[1]} entries, model {model.x_names}")
    return ReplayData(
        testbed=testbed,
        log=log,
        t=log.t,
        dt=testbed.sensors.dt,
        u=u,
        x=x,
        w=w,
        rate_names=rate_names,
        q=q,
        u_names=tuple(model.u_names),
        x_names=tuple(model.x_names),
        notes=tuple(notes),
    )


# ----------------------------------------------------------------------------
# windows and noise floor


@dataclass(frozen=True)
class Windows:
    """Consecutive multiple-shooting windows: ``starts[j] .. starts[j] + length - 1``."""

    starts: tuple
    length: int

    @property
    def n(self) -> int:
        return len(self.starts)

    def samples(self) -> np.ndarray:
        """Sample indices, shape (n_windows, length)."""
        return np.asarray(self.starts)[:, None] + np.arange(self.length)[None, :]

    def subset(self, which) -> Windows:
        """The windows at positions ``which``."""
        return Windows(tuple(self.starts[i] for i in which), self.length)


def make_windows(
    n: int, dt: float, *, window_s: float | None = None, source: str = "log"
) -> Windows:
    """Cut ``n`` samples into consecutive windows.

    Parameters
    ----------
    n : int
        Samples in the log.
    dt : float
        Sample period, s.
    window_s : float, optional
        Window length, s. Default ``min(DEFAULT_WINDOW_S, n dt / 4)``, at least
        ``MIN_WINDOW_SAMPLES`` samples.

    Raises
    ------
    InputError
        If the log gives fewer than ``MIN_WINDOWS`` windows of ``MIN_WINDOW_SAMPLES``.
    """
    need = MIN_WINDOWS * MIN_WINDOW_SAMPLES
    if n < need:
        raise InputError(
            f"{source}: too short to fit anything: {n} samples ({n * dt:.3g} s); the replay "
            f"needs at least {MIN_WINDOWS} windows of {MIN_WINDOW_SAMPLES} samples ({need} samples)"
        )
    if window_s is None:
        window_s = min(DEFAULT_WINDOW_S, n * dt / 4)
    if not (window_s > 0 and math.isfinite(window_s)):
        raise InputError(f"window {window_s!r} s: expected a positive length in s")
    length = max(MIN_WINDOW_SAMPLES, int(round(window_s / dt)))
    n_w = n // length
    if n_w < MIN_WINDOWS:
        raise InputError(
            f"{source}: {n} samples give {n_w} window(s) of {length} samples; need at least "
            f"{MIN_WINDOWS}: use a shorter window (now {window_s:g} s) or a longer log"
        )
    return Windows(tuple(j * length for j in range(n_w)), length)


@dataclass(frozen=True)
class NoiseFloor:
    """White measurement noise estimated from the data alone.

    Attributes
    ----------
    rate_axes : ndarray
        rad/s, 1-sigma per free rate axis.
    rate : float
        rad/s, RMS over the axes: the floor the gap is compared with.
    attitude : float or None
        rad, 1-sigma attitude noise per axis (dof 3), None for dof 1.
    """

    rate_axes: np.ndarray
    rate: float
    attitude: float | None


def _robust_sigma(d: np.ndarray, factor: float) -> np.ndarray:
    med = np.median(d, axis=0)
    return MAD_TO_SIGMA * np.median(np.abs(d - med), axis=0) / factor


def noise_floor(data: ReplayData) -> NoiseFloor:
    """Estimate the rate (and attitude) noise of a log from the data alone (see module doc)."""
    k = NOISE_DIFF_ORDER
    # var(D^k e) = C(2k, k) sigma^2 for white noise e
    sig = _robust_sigma(np.diff(data.w, n=k, axis=0), math.sqrt(math.comb(2 * k, k)))
    att = None
    if data.q is not None:
        q = data.q
        inc = quat.qmul(quat.qconj(q[:-1]), q[1:])  # body-frame attitude increment
        inc = inc * np.sign(inc[:, :1] + (inc[:, :1] == 0))
        phi = 2.0 * inc[:, 1:]
        e = phi - 0.5 * (data.w[:-1] + data.w[1:]) * data.dt  # trapezoidal integral of w
        s_e = float(np.sqrt(np.mean(_robust_sigma(e, 1.0) ** 2)))
        # e_k = n_{k+1} - n_k + dt (v_k + v_{k+1}) / 2: var = 2 sa^2 + dt^2 sw^2 / 2
        var = (s_e**2 - 0.5 * data.dt**2 * float(np.mean(sig**2))) / 2.0
        att = float(math.sqrt(max(var, 0.0)))
    return NoiseFloor(rate_axes=sig, rate=float(np.sqrt(np.mean(sig**2))), attitude=att)


# ----------------------------------------------------------------------------
# compiled Models


@lru_cache(maxsize=1)
def jit_available() -> bool:
    """True when CasADi can JIT-compile C code here (a C compiler answers).

    JIT changes how fast a rollout runs, never what it computes.
    """
    cc = os.environ.get("CC", "gcc")
    if shutil.which(cc) is None:
        return False
    x = ca.SX.sym("x")
    try:
        fn = ca.Function("jit_probe", [x], [2 * x], _jit_options())
        return float(fn(1.5)) == 3.0
    except RuntimeError:
        return False


def _jit_options() -> dict:
    cc = os.environ.get("CC", "gcc")
    jit = {
        "jit": True,
        "compiler": "shell",
        "jit_cleanup": True,
        "jit_temp_suffix": True,
        "jit_options": {"compiler": cc, "flags": ["-O1"], "verbose": False},
    }
    return {**jit, "der_options": dict(jit)}


def _effects_key(effects) -> tuple:
    if not effects:
        return ()
    return tuple(sorted((k, tuple(np.atleast_1d(v).tolist())) for k, v in dict(effects).items()))


@lru_cache(maxsize=32)
def _model_cached(testbed: Testbed, key: tuple) -> Model:
    effects = {k: (v[0] if len(v) == 1 else tuple(v)) for k, v in key}
    return build_model(testbed, effects)


def model_for(testbed: Testbed, effects=None) -> Model:
    """``build_model(testbed, effects)``, cached: the same testbed and effects give one Model."""
    return _model_cached(testbed, _effects_key(effects))


_COMPILED: dict = {}


def compiled_step(
    model: Model, dt: float, substeps: int = DEFAULT_SUBSTEPS, jit: bool | None = None
) -> ca.Function:
    """``Model.step(dt, substeps)``, JIT-compiled to C when a compiler is available.

    Compiled functions are kept per process and shared by every Model whose step
    is the same expression (testbeds that differ only in parameter values).

    Parameters
    ----------
    model : Model
    dt : float
        Sample period, s.
    substeps : int
        RK4 sub-steps per sample.
    jit : bool, optional
        Force (True) or forbid (False) compilation; default: when :func:`jit_available`.
    """
    step = model.step(dt, substeps)
    if jit is None:
        jit = jit_available()
    if not jit:
        return step
    key = step.serialize()
    if key not in _COMPILED:
        x, u, p = step.sx_in()
        _COMPILED[key] = ca.Function(
            "step_c", [x, u, p], step.call([x, u, p]), ["x", "u", "p"], ["x_next"], _jit_options()
        )
    return _COMPILED[key]


# ----------------------------------------------------------------------------
# the compiled multiple-shooting output error


@dataclass(frozen=True, eq=False)
class Fit:
    """One output-error fit of a :class:`ReplayProblem`.

    Attributes
    ----------
    theta : ndarray (k,)
        Fitted free parameters (SI units of the Model's parameters).
    theta_std : ndarray (k,)
        1-sigma uncertainty (Gauss-Newton covariance scaled by the reduced chi-square).
    p : ndarray
        The full parameter vector.
    delta : ndarray (n_delta, n_windows)
        Fitted initial-state perturbations.
    rss : float
        Weighted residual sum of squares (rates / sigma_w, attitude / sigma_q).
    n_res : int
        Number of weighted residuals.
    n_free : int
        Number of free variables (``k + delta.size``).
    gap : float
        rad/s, RMS rate output error (module doc).
    iterations : int
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
    extra: dict = field(default_factory=dict)  # "r", "J" (scipy CSC) at the fit


@lru_cache(maxsize=64)
def _window_functions(
    model: Model, L: int, K: int, rate_names: tuple, use_attitude: bool, substeps: int, jit
):
    """One window's weighted residual, and the residual with its Jacobian in ``[theta; delta]``.

    Inputs: ``delta, x_meas0, w_meas0, U (nu x L), W_meas (na x L), Q_meas (4 x L),
    p_base, S (n_p x K), theta (K), sigma = [sigma_w, sigma_q]``.
    """
    dof, na = model.dof, len(rate_names)
    n_lag = len(model.lag_index)
    nd = (3 if dof == 3 else 0) + na + n_lag
    nx_plant = model.nx - n_lag

    # ---- initial state: measured state (+) delta
    d = ca.SX.sym("delta", nd)
    xm = ca.SX.sym("x_meas", nx_plant)
    wm = ca.SX.sym("w_meas", na)
    if dof == 3:
        parts = [quat.qmul(xm[0:4], quat.qexp(d[0:3])), xm[4:7] + d[3:6], xm[7:]]
        k = 6
    else:
        parts = [xm[0], xm[1] + d[0], xm[2:]]
        k = 1
    if n_lag:
        # the lagged gyro starts near its measurement, free per window; the discrepancy
        # score counts these starts as parameters of the sensor_lag candidate
        parts.append(wm + d[k : k + n_lag])
    x0_fn = ca.Function("x0", [d, xm, wm], [ca.vertcat(*parts)])
    # ---- attitude error (rad): rotation vector of conj(q_model) (x) q_meas, small angles
    qa, qb = ca.SX.sym("qa", 4), ca.SX.sym("qb", 4)
    e = quat.qmul(quat.qconj(qa), qb)
    att_fn = ca.Function("att_err", [qa, qb], [2 * ca.sign(e[0] + 1e-300) * e[1:4]])

    D = ca.MX.sym("delta", nd)
    XM = ca.MX.sym("x_meas0", nx_plant)
    WM = ca.MX.sym("w_meas0", na)
    U = ca.MX.sym("U", model.nu, L)
    W = ca.MX.sym("W_meas", na, L)
    Q = ca.MX.sym("Q_meas", 4, L)
    PB = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    TH = ca.MX.sym("theta", K)
    SIG = ca.MX.sym("sigma", 2)
    P = PB + ca.mtimes(S, TH) if K else PB
    X0 = x0_fn(D, XM, WM)
    # Model.step (compiled), one mapaccum over the window
    step = compiled_step(model, 1.0 / model.testbed.sensors.rate, substeps, jit)
    X = step.mapaccum("rollout", L - 1, [0], [0])(X0, U[:, : L - 1], P)
    X_all = ca.horzcat(X0, X)
    Y = model.h.map(L)(X_all, U, P)
    w_rows = model.index(list(rate_names), "y")
    res = [ca.vec((W - Y[w_rows, :]) / SIG[0])]
    if use_attitude:
        q_rows = model.index(["qw", "qx", "qy", "qz"], "y")
        res.append(ca.vec(att_fn.map(L)(Y[q_rows, :], Q) / SIG[1]))
    r = ca.vertcat(*res)
    ins = [D, XM, WM, U, W, Q, PB, S, TH, SIG]
    names = [
        "delta",
        "x_meas0",
        "w_meas0",
        "U",
        "W_meas",
        "Q_meas",
        "p_base",
        "S",
        "theta",
        "sigma",
    ]
    win_r = ca.Function("window_r", ins, [r], names, ["r"])
    win_rj = ca.Function(
        "window_rj", ins, [r, ca.jacobian(r, ca.vertcat(TH, D))], names, ["r", "J"]
    )
    return win_r, win_rj


def _data_shapes(model: Model, L: int, nw: int, rate_names: tuple) -> list:
    na = len(rate_names)
    nx_plant = model.nx - len(model.lag_index)
    return [(nx_plant, nw), (na, nw), (model.nu, L * nw), (na, L * nw), (4, L * nw), (2, 1)]


@lru_cache(maxsize=64)
def _problem_functions(model, L, nw, K, rate_names, use_attitude, substeps, jit):
    """All windows' residual, and residual with Jacobian, the log's data an input (shared)."""
    win_r, win_rj = _window_functions(model, L, K, rate_names, use_attitude, substeps, jit)
    na = len(rate_names)
    nd = (3 if model.dof == 3 else 0) + na + len(model.lag_index)
    n = (na + (3 if use_attitude else 0)) * L
    v = ca.MX.sym("v", K + nd * nw)
    pb = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    shapes = _data_shapes(model, L, nw, rate_names)
    data = ca.MX.sym("data", sum(a * b for a, b in shapes))
    pieces, i = [], 0
    for a, b in shapes:
        pieces.append(ca.reshape(data[i : i + a * b], a, b))
        i += a * b
    th, D = v[:K], ca.reshape(v[K:], nd, nw)
    args = [D, *pieces[:5], pb, S, th, pieces[5]]
    R = win_r.map(nw, "thread", 2)(*args)
    Rj, Jj = win_rj.map(nw, "thread", 2)(*args)
    # columns of window j's Jacobian: [theta (K), delta_j (nd)]
    blocks = [Jj[:, j * (K + nd) : (j + 1) * (K + nd)] for j in range(nw)]
    J_th = ca.vertcat(*[blk[:, :K] for blk in blocks]) if K else ca.MX(n * nw, 0)
    J = ca.horzcat(J_th, ca.diagcat(*[blk[:, K:] for blk in blocks]))
    fr = ca.Function("r", [v, pb, S, data], [ca.vec(R)])
    fj = ca.Function("rj", [v, pb, S, data], [ca.vec(Rj), J])
    return fr, fj


@lru_cache(maxsize=64)
def _problem_solver(model, L, nw, K, rate_names, use_attitude, substeps, jit):
    """IPOPT on ``z = v / scale``: objective 0.5 |r|^2, gradient J^T r, Hessian J^T J.

    Gauss-Newton: no second derivatives through the rollout. Shared by every log
    with the same Model and window layout: ``p_base``, ``S``, ``scale`` and the
    log's data are solver parameters.
    """
    fr, fj = _problem_functions(model, L, nw, K, rate_names, use_attitude, substeps, jit)
    na = len(rate_names)
    nd = (3 if model.dof == 3 else 0) + na + len(model.lag_index)
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
        {"x": z, "p": par, "f": 0.5 * ca.sumsqr(fr(z * scale, pb, S, data))},
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


class ReplayProblem:
    """The multiple-shooting output error of one Model on one log.

    One window is one CasADi Function: the measured initial state corrected by
    ``delta``, the open-loop ``Model.step`` rolled over the window (``mapaccum``),
    the Model's measurement, the weighted residual and its exact Jacobian in
    ``[theta; delta]`` (forward AD). All windows are one ``map`` of it (two
    threads). The free parameters enter as ``p = p_base + S theta`` with ``S`` an
    input, so one compiled window serves every choice of free parameters.

    Parameters
    ----------
    model : Model
        The Model (any effects); parameters enter as the vector ``p``.
    data : ReplayData
    windows : Windows
    floor : NoiseFloor
        Noise levels that weight the residuals.
    substeps : int
        RK4 sub-steps per sample of the rollout.
    use_attitude : bool
        Include the attitude error of a dof-3 log in the fit objective.
    jit : bool, optional
        Compile the Model's step to C (default: when a compiler is available).
    theta_slots : int
        Fits with up to this many free parameters share one compiled Jacobian.

    Notes
    -----
    Residual layout: window after window; within a window the ``n_axes * L`` rate
    residuals ``(w_meas - w_model) / sigma_w`` (sample-major), then, for dof 3,
    the ``3 L`` attitude residuals ``2 vec(conj(q_model) (x) q_meas) / sigma_q``.
    """

    def __init__(
        self,
        model: Model,
        data: ReplayData,
        windows: Windows,
        floor: NoiseFloor,
        *,
        substeps: int = DEFAULT_SUBSTEPS,
        use_attitude: bool = True,
        jit: bool | None = None,
        theta_slots: int = THETA_SLOTS,
    ) -> None:
        self.model, self.data, self.windows, self.floor = model, data, windows, floor
        self.theta_slots = int(theta_slots)
        self.substeps, self.jit = int(substeps), jit
        na = data.n_axes
        nw, L = windows.n, windows.length
        self.sigma_w = max(floor.rate, RATE_SIGMA_MIN)
        self.use_attitude = bool(use_attitude and model.dof == 3)
        self.sigma_q = max(floor.attitude or 0.0, ATTITUDE_SIGMA_MIN)
        self.n_delta = (3 if model.dof == 3 else 0) + na + len(model.lag_index)
        idx = windows.samples()  # (nw, L)
        self._idx = idx
        flat = idx.reshape(-1)
        starts = list(windows.starts)
        # window data, horizontally concatenated window after window
        self._xm = data.x[starts].T
        self._wm = data.w[starts].T
        self._U = data.u[flat].T
        self._W = data.w[flat].T
        self._Q = data.q[flat].T if self.use_attitude else np.zeros((4, len(flat)))
        self._sig = np.array([self.sigma_w, self.sigma_q])
        self.n_win_res = (na + (3 if self.use_attitude else 0)) * L
        self.n_res = self.n_win_res * nw
        self.n_rate_res = na * L * nw
        rate_mask = np.zeros(self.n_win_res, dtype=bool)
        rate_mask[: na * L] = True
        self.rate_mask = np.tile(rate_mask, nw)
        self._data = self._data_vector()

    # ------------------------------------------------------------------ window functions
    def _window(self, K: int):
        return _window_functions(
            self.model,
            self.windows.length,
            K,
            self.data.rate_names,
            self.use_attitude,
            self.substeps,
            self.jit,
        )

    def _key(self, K: int) -> tuple:
        return (
            self.model,
            self.windows.length,
            self.windows.n,
            K,
            self.data.rate_names,
            self.use_attitude,
            self.substeps,
            self.jit,
        )

    def _data_vector(self) -> np.ndarray:
        """The log's window data as one vector (a parameter of the shared Functions)."""
        parts = (self._xm, self._wm, self._U, self._W, self._Q, self._sig)
        return np.concatenate([np.asarray(a, dtype=float).reshape(-1, order="F") for a in parts])

    def _functions(self, K: int):
        """``r(v, p_base, S, data)`` and ``(r, J)(...)`` with ``v = [theta; vec(delta)]``."""
        return _problem_functions(*self._key(K))

    def _eval(self, which: int, v, p_base, S):
        return self._functions(S.shape[1])[which](v, p_base, S, self._data)

    def residual(self, delta: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Weighted residual at ``delta`` (n_delta, n_windows) and parameters ``p``."""
        S, K = self._pad(np.zeros((self.model.n_p, 0)))
        v = np.r_[np.zeros(K), np.asarray(delta, dtype=float).reshape(-1, order="F")]
        return np.asarray(self._eval(0, v, p, S)).ravel()

    def gap_of(self, delta: np.ndarray, p: np.ndarray) -> float:
        """rad/s, RMS rate output error at ``delta``, ``p`` (module doc)."""
        r = self.residual(delta, p)[self.rate_mask]
        return float(self.sigma_w * np.sqrt(np.mean(r**2)))

    def predicted(self, delta: np.ndarray, p: np.ndarray) -> dict:
        """The Model's rate output on every window sample: ``index``, ``t``, ``w`` (N_used, na)."""
        r = self.residual(delta, p)[self.rate_mask]
        na = self.data.n_axes
        idx = self._idx.reshape(-1)
        w_meas = self.data.w[idx]
        w_model = w_meas - self.sigma_w * r.reshape(-1, na)
        return {"index": idx, "t": self.data.t[idx], "w": w_model}

    def _pad(self, S: np.ndarray):
        k = S.shape[1]
        K = max(self.theta_slots, k)
        return np.hstack([S, np.zeros((S.shape[0], K - k))]), K

    def jacobian(self, fit: Fit, S: np.ndarray | None = None):
        """Weighted residual ``r`` and its Jacobian (scipy sparse) in ``[theta; vec(delta)]``."""
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        k = S.shape[1]
        Sp, K = self._pad(S)
        v = np.concatenate([fit.theta, np.zeros(K - k), fit.delta.reshape(-1, order="F")])
        p_base = fit.p - S @ fit.theta if k else fit.p
        r, J = self._eval(1, v, p_base, Sp)
        J = J.sparse().tocsc()
        keep = np.r_[np.arange(k), np.arange(K, J.shape[1])]
        return np.asarray(r).ravel(), J[:, keep]

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
            Start of the initial-state perturbations (default 0: the measured states).
        name : str
            Names the problem in a SolverError.

        Returns
        -------
        Fit

        Raises
        ------
        SolverError
            If IPOPT does not converge or the replay is not finite.
        """
        p_base = np.asarray(p_base, dtype=float)
        S = np.zeros((self.model.n_p, 0)) if S is None else np.asarray(S, dtype=float)
        k = S.shape[1]
        Sp, K = self._pad(S)
        nd, nw = self.n_delta, self.windows.n
        th0 = np.zeros(k) if theta0 is None else np.asarray(theta0, dtype=float)
        d0 = np.zeros((nd, nw)) if delta0 is None else np.asarray(delta0, dtype=float)
        v0 = np.concatenate([th0, np.zeros(K - k), d0.reshape(-1, order="F")])
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
        status = stats.get("return_status", "?")
        if status not in _IPOPT_OK:
            raise SolverError(f"{name}: IPOPT did not converge ({status})")
        v = np.asarray(sol["x"]).ravel() * scale
        r, J = self._eval(1, v, p_base, Sp)
        r = np.asarray(r).ravel()
        if not np.all(np.isfinite(r)):
            raise SolverError(f"{name}: the fitted replay is not finite")
        keep = np.r_[np.arange(k), np.arange(K, v.size)]
        v, scale = v[keep], scale[keep]
        J = J.sparse().tocsc()[:, keep]
        rss = float(r @ r)
        n_free = v.size
        theta = v[:k]
        std = np.full(k, np.nan)
        if k:
            Js = J.toarray() * scale[None, :]
            cov_s = np.linalg.pinv(Js.T @ Js) * (rss / max(self.n_res - n_free, 1))
            std = np.sqrt(np.abs(np.diag(cov_s)[:k])) * scale[:k]
        p = p_base + S @ theta if k else p_base.copy()
        gap = float(self.sigma_w * np.sqrt(np.mean(r[self.rate_mask] ** 2)))
        return Fit(
            theta=theta,
            theta_std=std,
            p=p,
            delta=v[k:].reshape(nd, nw, order="F"),
            rss=rss,
            n_res=self.n_res,
            n_free=n_free,
            gap=gap,
            iterations=int(stats.get("iter_count", 0)),
            status=status,
            extra={"r": r, "J": J},
        )


# ----------------------------------------------------------------------------
# the whole log from its first sample, and a one-call replay


def open_loop(
    model: Model, data: ReplayData, p: np.ndarray | None = None, *, substeps: int = DEFAULT_SUBSTEPS
):
    """The Model from the log's first measured state over the whole log, no restart.

    Returns
    -------
    ndarray (N, n_axes)
        Model rate output at every sample, rad/s (one compiled ``mapaccum``).
    """
    p = model.p0 if p is None else np.asarray(p, dtype=float)
    x0 = data.x[0]
    if model.lag_index:
        x0 = np.concatenate([x0, np.asarray(model.lag_init(x0, data.u[0], p)).ravel()])
    roll = model.rollout(data.n - 1, data.dt, substeps)
    X = np.hstack([x0[:, None], np.asarray(roll(x0, data.u[:-1].T, p))])
    Y = np.asarray(model.h.map(data.n)(X, data.u.T, p)).T
    return Y[:, model.index(list(data.rate_names), "y")]


@dataclass(frozen=True, eq=False)
class Replay:
    """A replay of a log by a Model: the fit of the window initial states and the gap."""

    model: Model
    data: ReplayData
    windows: Windows
    floor: NoiseFloor
    fit: Fit
    problem: ReplayProblem

    @property
    def gap(self) -> float:
        """rad/s, RMS rate output error (module doc)."""
        return self.fit.gap

    def residuals(self) -> dict:
        """``t`` (N_used,), ``w_meas``, ``w_model``, ``residual`` (N_used, n_axes), rad/s."""
        pr = self.problem.predicted(self.fit.delta, self.fit.p)
        w_meas = self.data.w[pr["index"]]
        return {
            "index": pr["index"],
            "t": pr["t"],
            "w_meas": w_meas,
            "w_model": pr["w"],
            "residual": w_meas - pr["w"],
        }


def replay(
    testbed: Testbed,
    log: Log,
    *,
    effects=None,
    window_s: float | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
) -> Replay:
    """Replay ``log`` with ``testbed``'s Model (plus ``effects``) and measure the gap.

    Parameters
    ----------
    testbed : Testbed
        Nominal testbed (its ``[effects]`` included).
    log : Log
        The measured run.
    effects : mapping, optional
        Extra effects (FORMATS.md names and units) in the Model.
    window_s : float, optional
        Multiple-shooting window, s (see :func:`make_windows`).
    substeps : int
        RK4 sub-steps per sample.

    Returns
    -------
    Replay
        ``.gap`` (rad/s), ``.floor.rate`` (rad/s), ``.residuals()``.
    """
    data = replay_data(testbed, log)
    windows = make_windows(data.n, data.dt, window_s=window_s, source=log.source)
    floor = noise_floor(data)
    model = build_model(testbed, effects)
    problem = ReplayProblem(model, data, windows, floor, substeps=substeps)
    fit = problem.fit(model.p0, name=f"replay of {log.source}: initial states of the windows")
    return Replay(model, data, windows, floor, fit, problem)
