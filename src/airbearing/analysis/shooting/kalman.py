"""The extended-Kalman-filter likelihood of a whole log: effects, process-noise intensity and
measurement noise as the parameters of one optimisation, cost linear in the samples.

The Model is the engine's (:meth:`Model.step_dt`, its RK4 step on the logged intervals, and
its measurement ``h``), and so is the front end (:func:`.logs.replay_data`: inputs, the
measured outputs, segments and outlier rows). The filter runs sample by sample:

Predict (from row ``k-1`` to row ``k``, the input held over the logged interval ``dt``)
    ``x- = step(x+, u, p, dt)``, ``P- = F P+ F^T + Q`` with ``F = d step / d x`` (CasADi's
    exact Jacobian of the RK4 step, no finite differences). The unexplained torque is white
    and held over each interval (zero-order hold, as the engine holds every input), so its
    covariance is exact for the discrete model: ``Q = sigma_w^2 g g^T / dt`` with ``g = (d
    step / d tau) / (d wdot / d tau)`` the state's response to the torque, per unit rate
    change it would cause (``tau`` the Model's disturbance torque input ``tau_z``). On the
    rate ``Q = sigma_w^2 dt``: ``sigma_w`` (rad/s per sqrt(s)) is the random-walk intensity
    of the rate, the :class:`.process_noise.ProcessNoise` ``intensity``.
Update (row ``k``)
    ``e = y - h(x-)``, ``S = H P- H^T + R``, ``K = P- H^T S^-1``, ``x+ = x- + K e``, ``P+`` by
    Joseph's form (symmetric, positive for any gain). ``R = diag(sigma_y^2)``, one sigma per
    measured output (yaw, rate), estimated or given. An entry that is missing (NaN in
    :class:`KalmanData`, every entry of an outlier row) is skipped: its row of ``H`` and its
    innovation are zero and its variance one, so it adds nothing to the likelihood or the
    state.
Likelihood
    ``NLL = sum_k 0.5 (log det S_k + e_k^T S_k^-1 e_k + n_k log 2 pi)`` (the prediction-error
    decomposition; exact for a linear Gaussian model, first order in the EKF).
Segments
    A segment (FORMATS.md gaps, input glitches) starts afresh: the state is reset to the
    front end's start estimate with a broad covariance ``P0`` (:data:`P0_ATTITUDE`,
    :data:`P0_RATE`; measured extra states such as gimbal angles exactly), nothing is
    integrated across a gap.

Cost
    One sample is one CasADi Function of a few hundred instructions. Its derivatives are
    carried FORWARD with the filter: with the few variables ``z`` (effects, ``log
    sigma_w``, ``log sigma_y``) as directions, the carry's sensitivity ``dc/dz`` (and for
    the Hessian its second derivative) is propagated by CasADi's exact derivatives of the
    sample, so the NLL's gradient and exact Hessian come out of one pass, and nothing of
    the pass is stored: time linear in the samples, memory that of the log. A block of
    :data:`BLOCK` samples (a ``mapaccum``, a graph of constant size) is compiled to C once
    per Model structure and number of variables through the engine's on-disk cache
    (:func:`.functions.compiled`), whatever the log's length; a Python loop runs the
    blocks (a log is padded with rows of no effect to whole blocks). Reverse mode through
    a ``mapaccum`` of the whole log was tried first: its graph and C code depend on the
    log's length (one compilation per length, 20 s for the Hessian) and it stores every
    sample's carry.

Optimiser
    scipy's L-BFGS-B on the compiled NLL and its exact gradient, in variables scaled by the
    NLL's exact Hessian at the start (one unit is one standard error), the log intensity
    bounded below (:data:`LOG_INTENSITY_MIN`: no process noise is a boundary, not a
    minimum at minus infinity). Chosen over IPOPT with the exact Hessian: a Hessian costs
    several gradients and L-BFGS-B on a scaled problem of at most a few tens of
    parameters converges in a few tens of gradients with no Hessian at all; the exact
    Hessian is evaluated twice: at the start on the first :data:`SCALE_BLOCKS` blocks
    (scaling) and at the optimum on the whole log (the observed information, whose
    inverse gives the standard errors).

Assumptions and limits
    dof 1 (a yaw rig, a yaw CMG), without reaction wheels. The noises are white and
    Gaussian; the filter linearises the Model about its estimate at each sample (an EKF:
    first order, good while the state's uncertainty is small against the scale of the
    Model's nonlinearity, which for friction and drag on a gyro or attitude log of usual
    noise it is). The standard errors are those of the observed information (asymptotic,
    the parameters away from their bounds); an intensity at its lower bound has none;
    ``test_intensity`` tests it against zero (likelihood ratio). Not built: dof 3 (it
    needs an error-state filter, a three-component attitude error about the estimated
    quaternion; with this forward scheme its second-order block would be, by estimate, 10^6
    instructions), reaction wheels, coloured measurement noise.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as so
from scipy.stats import chi2

from airbearing.analysis.shooting.functions import DEFAULT_SUBSTEPS
from airbearing.analysis.shooting.kalman_data import (
    P0_ATTITUDE,
    P0_RATE,
    KalmanData,
    _check_data,
    _check_model,
    _p0,
    _rows,
    kalman_data,
)
from airbearing.analysis.shooting.kalman_filter import BLOCK, _block_functions, _Problem
from airbearing.analysis.shooting.logs import ReplayData, noise_floor, replay_data
from airbearing.errors import InputError, SolverError
from airbearing.io.log import Log
from airbearing.models.model import Model

__all__ = [
    "KalmanData",
    "KalmanFit",
    "LOG_INTENSITY_MIN",
    "P0_ATTITUDE",
    "P0_RATE",
    "fit_kalman",
    "kalman_data",
    "kalman_nll",
    "BLOCK",
]

#: Lower bound of ``log(sigma_w)`` (sigma_w in rad/s per sqrt(s)): 1e-12 rad/s per sqrt(s)
#: moves a rate by 1e-10 rad/s in 3 hours, no process noise for any log.
LOG_INTENSITY_MIN = math.log(1e-12)
#: Bounds of ``log(sigma_y)`` (rad or rad/s) of an estimated measurement noise.
LOG_NOISE_BOUNDS = (math.log(1e-9), math.log(10.0))
#: L-BFGS-B: iteration limit and the projected-gradient tolerance (scaled variables: one
#: unit is about one standard error, so 1e-5 is far below any statistical precision).
MAX_ITER = 300
GTOL = 1e-5
#: p-value below which the unexplained torque is significant (as the linked pieces').
SIGNIFICANCE = 1e-3
#: Blocks whose Hessian scales the variables at the start (:func:`fit_kalman`).
SCALE_BLOCKS = 16


# ----------------------------------------------------------------------------
# the fit


@dataclass(frozen=True)
class KalmanFit:
    """The maximum-likelihood fit of the Kalman likelihood.

    Attributes
    ----------
    names : tuple of str
        The free parameters (``Model.p_names``).
    estimates, std : ndarray
        Their estimates and standard errors (SI units of ``p_names``); NaN std when the
        observed information is not positive definite.
    intensity : float
        ``sigma_w``, rad/s per sqrt(s): the random-walk intensity of the rate (a white
        torque of spectral density ``(J sigma_w)^2`` N^2 m^2 s); 0 when fixed at 0.
    intensity_std : float
        Its standard error (delta method from ``log sigma_w``); NaN when fixed or at the
        lower bound :data:`LOG_INTENSITY_MIN`.
    noise : dict
        Output name -> measurement noise sigma (rad or rad/s), estimated or given.
    noise_std : dict
        Output name -> its standard error (NaN when given).
    nll : float
        The negative log-likelihood at the optimum (nats).
    iterations : int
        L-BFGS-B iterations.
    evaluations : int
        NLL-and-gradient evaluations (of both fits with ``test_intensity``).
    seconds : float
        Wall time of the fit, s (compilation included when it happened).
    rows : int
        Rows of the log; ``observations`` the measured entries used.
    observations : int
    covariance : ndarray
        Covariance of ``z = [theta; log sigma_w; log sigma_y]`` (inverse observed
        information in the estimated entries; zero rows and columns for fixed ones).
    message : str
        The optimiser's message.
    lr : float
        With ``test_intensity``: the likelihood-ratio statistic ``2 (NLL_0 - NLL)``
        against the same fit without process noise (NaN when not tested).
    p : float
        Its p-value, a 50:50 mixture of chi2(0) and chi2(1) (zero intensity is on the
        boundary; Self & Liang 1987), NaN when not tested.
    """

    names: tuple
    estimates: np.ndarray
    std: np.ndarray
    intensity: float
    intensity_std: float
    noise: dict
    noise_std: dict
    nll: float
    iterations: int
    evaluations: int
    seconds: float
    rows: int
    observations: int
    covariance: np.ndarray = field(repr=False)
    message: str = ""
    lr: float = math.nan
    p: float = math.nan

    @property
    def significant(self) -> bool | None:
        """``p < SIGNIFICANCE``: the unexplained torque is real (None when not tested)."""
        return None if math.isnan(self.p) else bool(self.p < SIGNIFICANCE)

    def to_json(self) -> dict:
        """The JSON form: plain numbers, ``null`` for a missing standard error."""

        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        return {
            "effects": [
                {"name": n, "value": num(v), "std": num(e)}
                for n, v, e in zip(self.names, self.estimates, self.std, strict=True)
            ],
            "intensity": num(self.intensity),
            "intensity_std": num(self.intensity_std),
            "intensity_unit": "rad/s/sqrt(s)",
            "noise": {k: num(v) for k, v in self.noise.items()},
            "noise_std": {k: num(v) for k, v in self.noise_std.items()},
            "nll": num(self.nll),
            "iterations": self.iterations,
            "evaluations": self.evaluations,
            "seconds": num(self.seconds),
            "rows": self.rows,
            "observations": self.observations,
            "message": self.message,
            "lr": num(self.lr),
            "p": num(self.p),
            "significant": self.significant,
        }

    def estimate(self, name: str) -> tuple[float, float]:
        """``(estimate, std)`` of one free parameter by name."""
        if name not in self.names:
            raise InputError(f"kalman fit: no free parameter {name!r}; it has {list(self.names)}")
        i = self.names.index(name)
        return float(self.estimates[i]), float(self.std[i])


def _free_selection(model: Model, free) -> tuple[tuple, np.ndarray]:
    free = (free,) if isinstance(free, str) else tuple(free or ())
    unknown = [n for n in free if n not in model.p_names]
    if unknown:
        raise InputError(
            f"kalman: free {unknown}: not parameters of the Model; expected names from "
            f"{list(model.p_names)}"
        )
    if len(set(free)) != len(free):
        raise InputError(f"kalman: free {list(free)}: a parameter is named twice")
    S = np.zeros((model.n_p, len(free)))
    for j, n in enumerate(free):
        S[model.p_names.index(n), j] = 1.0
    return free, S


def _prepare(model, data, free, substeps, jit, p_base=None):
    _check_model(model)
    if isinstance(data, Log):
        data = replay_data(model.testbed, data)
    kd = kalman_data(data, model) if isinstance(data, ReplayData) else data
    _check_data(model, kd)
    free, S = _free_selection(model, free)
    y_rows = tuple(model.index(list(kd.y_names), "y"))
    blocks = _block_functions(model, y_rows, len(free), substeps, jit, kd.n)
    n_pad = BLOCK * math.ceil(kd.n / BLOCK)
    D = _rows(model, kd, n_pad).reshape(n_pad // BLOCK, BLOCK, -1)
    pb = (
        model.p0 - S @ model.p0[[model.p_names.index(n) for n in free]]
        if p_base is None
        else p_base
    )
    k = np.r_[pb, S.ravel(order="F"), _p0(model)]
    nc = model.nx + model.nx**2 + 1
    return kd, free, S, _Problem(blocks, D, k, nc, kd.n)


def _noise_start(data, kd: KalmanData) -> dict:
    """A first guess of each output's noise sigma: the engine's noise floor of the log, or
    the scatter of the first differences of the arrays."""
    out = {}
    floor = noise_floor(data) if isinstance(data, ReplayData) else None
    for j, name in enumerate(kd.y_names):
        v = None
        if floor is not None:
            v = floor.rate if name == "wz" else floor.attitude
        if v is None or not v > 0:
            d = np.diff(kd.y[:, j])
            d = d[np.isfinite(d)]
            v = float(np.median(np.abs(d - np.median(d)))) * 1.4826 / math.sqrt(2) if d.size else 0
        out[name] = max(float(v), 1e-8)
    return out


def kalman_nll(
    model: Model,
    data,
    *,
    p=None,
    intensity: float = 0.0,
    noise: dict,
    order: int = 0,
    substeps: int = DEFAULT_SUBSTEPS,
    jit: bool | None = None,
):
    """The negative log-likelihood of a log under the Model, and its exact derivatives.

    Parameters
    ----------
    model : Model
        dof-1 Model (module doc).
    data : Log, ReplayData or KalmanData
        The log (as in :func:`fit_kalman`).
    p : array_like (n_p,), optional
        Parameters, SI (default ``model.p0``).
    intensity : float
        ``sigma_w``, rad/s per sqrt(s), of the unexplained torque (module doc); 0: none.
    noise : dict
        Output name (``yaw``, ``wz``) -> measurement noise sigma, rad or rad/s.
    order : {0, 1, 2}
        0: the NLL; 1: also its gradient; 2: also its Hessian, both in ``z = [p; log
        sigma_w; log sigma_y]`` (all parameters; ``log sigma_w`` has zero derivatives when
        ``intensity`` is 0).
    substeps : int
        RK4 sub-steps per sample.
    jit : bool, optional
        False: CasADi's virtual machine; default: compiled when a C compiler exists.

    Returns
    -------
    float, or tuple
        The NLL (nats), then the gradient (n_p + 1 + ny,) and the Hessian.
    """
    _check_model(model)
    p = model.p0 if p is None else np.asarray(p, float)
    if p.shape != (model.n_p,):
        raise InputError(f"kalman_nll: p has shape {p.shape}, expected ({model.n_p},)")
    if order not in (0, 1, 2):
        raise InputError(f"kalman_nll: order {order!r}: expected 0, 1 or 2")
    names = model.p_names if order else ()
    pb = np.zeros(model.n_p) if order else p
    kd, _, _, prob = _prepare(model, data, names, substeps, jit, p_base=pb)
    missing = [k for k in kd.y_names if k not in noise]
    if missing:
        raise InputError(f"kalman_nll: noise has no sigma for outputs {missing}")
    lsw = math.log(intensity) if intensity > 0 else -700.0
    lsy = [math.log(noise[k]) for k in kd.y_names]
    z = np.r_[p, lsw, lsy] if order else np.r_[lsw, lsy]
    if order == 0:
        return prob.nll(z)
    f, g = prob.nll_grad(z)
    return (f, g) if order == 1 else (f, g, prob.hess(z))


def fit_kalman(
    model: Model,
    data,
    free=(),
    *,
    intensity: float | None = None,
    noise: dict | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    jit: bool | None = None,
    max_iter: int = MAX_ITER,
    test_intensity: bool = False,
) -> KalmanFit:
    """Maximise the Kalman likelihood of a log over effects, intensity and noise.

    Parameters
    ----------
    model : Model
        dof-1 Model holding the effects to estimate (their values are the start).
    data : Log, ReplayData or KalmanData
        The log (a Log of the Model's testbed is read by
        :func:`airbearing.analysis.shooting.logs.replay_data`), or :func:`kalman_data`
        arrays with missing entries as NaN.
    free : sequence of str
        Parameters to estimate (``model.p_names``, e.g. ``viscous_friction``), SI units.
    intensity : float, optional
        ``sigma_w``, rad/s per sqrt(s): fixed at this value (0: no process noise, the
        output-error likelihood); default estimated.
    noise : dict, optional
        Output name (``yaw``, ``wz``) -> measurement noise sigma (rad, rad/s), fixed;
        outputs not named are estimated (default: all).
    substeps : int
        RK4 sub-steps per sample (the engine's :data:`.functions.DEFAULT_SUBSTEPS`).
    jit : bool, optional
        False: CasADi's virtual machine (same values, slower); default compiled when a C
        compiler is available.
    max_iter : int
        L-BFGS-B iteration limit.
    test_intensity : bool
        With an estimated intensity: also fit without process noise (warm-started, no
        Hessian) for the likelihood-ratio test :attr:`KalmanFit.p` (about half as many
        gradient passes again).

    Returns
    -------
    KalmanFit

    Raises
    ------
    InputError
        A free name that is not a parameter, a noise for an output the log lacks, a
        non-positive fixed intensity or noise, a log the filter cannot read.
    SolverError
        When L-BFGS-B stops without converging or the likelihood is not finite at the start.
    """
    t0 = time.perf_counter()
    _check_model(model)
    if isinstance(data, Log):
        data = replay_data(model.testbed, data)
    kd, free, S, prob = _prepare(model, data, free, substeps, jit)
    K = len(free)
    noise = dict(noise or {})
    bad = [k for k in noise if k not in kd.y_names]
    if bad:
        raise InputError(f"kalman: noise for {bad}: the log measures only {list(kd.y_names)}")
    for k, v in noise.items():
        if not (isinstance(v, (int, float)) and v > 0 and math.isfinite(v)):
            raise InputError(f"kalman: noise[{k!r}] = {v!r}: expected a positive sigma")
    if intensity is not None and not (intensity >= 0 and math.isfinite(intensity)):
        raise InputError(f"kalman: intensity {intensity!r}: expected sigma_w >= 0 rad/s/sqrt(s)")
    guess = _noise_start(data, kd)
    theta0 = model.p0[[model.p_names.index(n) for n in free]]
    lsy0 = np.array([math.log(noise.get(k, guess[k])) for k in kd.y_names])
    if intensity is None:
        # a start well inside: the rate's noise over a tenth of the log per sqrt(s)
        sw0 = 0.1 * guess.get("wz", guess[kd.y_names[0]]) / math.sqrt(max(kd.t[-1] - kd.t[0], 1e-9))
        lsw0 = math.log(max(sw0, 1e-10))
    else:
        lsw0 = math.log(intensity) if intensity > 0 else LOG_INTENSITY_MIN - 600.0
    z0 = np.r_[theta0, lsw0, lsy0]
    est = np.r_[np.ones(K, bool), intensity is None, [k not in noise for k in kd.y_names]]
    f0, _ = prob.nll_grad(z0)
    if not math.isfinite(f0):
        raise SolverError(f"{kd.source}: the Kalman likelihood is not finite at the start")
    # scale: one unit of each estimated variable is about one standard error at the start
    # (from the first SCALE_BLOCKS blocks, times the log's length over theirs: a scale
    # needs no more; the Hessian is the dearest pass, 10 gradients' worth)
    m = min(len(prob.D), SCALE_BLOCKS)
    H0 = prob.hess(z0, m) * (len(prob.D) / m)
    d = np.abs(np.diag(H0))[est]
    scale = np.ones(len(z0))
    scale[est] = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
    scale[K:][est[K:]] = np.minimum(scale[K:][est[K:]], 1.0)
    count = {"n": 0}

    def minimise(z_start, mask):
        """L-BFGS-B over the entries ``mask`` of ``z`` from ``z_start``, scaled by ``scale``."""
        idx = np.flatnonzero(mask)
        lo = np.full(idx.size, -np.inf)
        hi = np.full(idx.size, np.inf)
        for j, i in enumerate(idx):
            if i == K:
                lo[j] = (LOG_INTENSITY_MIN - z_start[i]) / scale[i]
            elif i > K:
                lo[j] = (LOG_NOISE_BOUNDS[0] - z_start[i]) / scale[i]
                hi[j] = (LOG_NOISE_BOUNDS[1] - z_start[i]) / scale[i]
        f_start, _ = prob.nll_grad(z_start)

        def fun(s):
            z = z_start.copy()
            z[idx] += s * scale[idx]
            count["n"] += 1
            v, g = prob.nll_grad(z)
            if not math.isfinite(v):
                return 1e300, np.zeros(idx.size)
            return v - f_start, g[idx] * scale[idx]

        res = so.minimize(
            fun,
            np.zeros(idx.size),
            jac=True,
            method="L-BFGS-B",
            bounds=list(zip(lo, hi, strict=True)),
            options={"maxiter": int(max_iter), "gtol": GTOL, "ftol": 1e-15, "maxcor": 20},
        )
        z = z_start.copy()
        z[idx] += res.x * scale[idx]
        nll, g = prob.nll_grad(z)
        if not res.success and np.max(np.abs(g[idx] * scale[idx])) > 1e-2:
            raise SolverError(f"{kd.source}: the Kalman fit did not converge: {res.message}")
        return z, nll, res

    z, nll, res = minimise(z0, est)
    lr = p_value = math.nan
    if test_intensity and intensity is None:
        # the same likelihood without process noise, from the estimates: the boundary
        # test of the intensity (chi2 mixture, as the linked pieces' ProcessNoise)
        z_null = z.copy()
        z_null[K] = LOG_INTENSITY_MIN - 600.0
        mask = est.copy()
        mask[K] = False
        _, nll_null, _ = minimise(z_null, mask)
        lr = max(2.0 * (nll_null - nll), 0.0)
        p_value = 0.5 * float(chi2.sf(lr, 1)) if lr > 0 else 1.0
    H = prob.hess(z)
    cov = np.zeros((len(z), len(z)))
    inner = est.copy()
    if intensity is None and z[K] <= LOG_INTENSITY_MIN + 1e-6:
        inner[K] = False  # at the bound: no curvature to invert
    ii = np.flatnonzero(inner)
    Hs = H[np.ix_(ii, ii)]
    try:
        np.linalg.cholesky(Hs)
        cov[np.ix_(ii, ii)] = np.linalg.inv(Hs)
    except np.linalg.LinAlgError:
        cov[np.ix_(ii, ii)] = np.nan
    sd = np.sqrt(np.abs(np.diag(cov)))
    sd[~inner] = np.nan
    sw = math.exp(z[K]) if (intensity is None or intensity > 0) else 0.0
    if intensity is None and not inner[K]:
        sw = 0.0
    noise_out = {k: noise.get(k, math.exp(z[K + 1 + j])) for j, k in enumerate(kd.y_names)}
    noise_sd = {k: noise_out[k] * sd[K + 1 + j] for j, k in enumerate(kd.y_names)}
    return KalmanFit(
        names=free,
        estimates=z[:K].copy(),
        std=sd[:K].copy(),
        intensity=sw,
        intensity_std=sw * sd[K] if inner[K] else math.nan,
        noise=noise_out,
        noise_std=noise_sd,
        nll=float(nll),
        iterations=int(res.nit),
        evaluations=count["n"],
        seconds=time.perf_counter() - t0,
        rows=kd.n,
        observations=int(np.isfinite(kd.y).sum()),
        covariance=cov,
        message=str(res.message),
        lr=lr,
        p=p_value,
    )
