"""Process noise: what the Model does not explain, estimated with the effects.

Grey-box stochastic modelling (Kristensen, Madsen & Joergensen 2004, CTSM; the smoother
form of multiple shooting): the windows of a segment are LINKED (:class:`.WindowSet`
``link``), but instead of forcing the continuity defects to zero they are penalised by
the covariance of a random torque the Model does not contain. A white torque noise makes
each rate axis a random walk of intensity ``sigma_w`` (rad/s per sqrt(s)); over a
hand-over interval ``T`` the defect of (attitude, rate) on one axis is Gaussian with
covariance (the integrated Wiener process)::

    sigma_w^2 [[T^3 / 3, T^2 / 2],
               [T^2 / 2, T      ]]

(the rate alone, ``sigma_w^2 T``, when the attitude is not fitted; a lagged gyro state
like the rate). The whitened defects ``W c`` join the measurement residual, so one
Gauss-Newton fit gives the maximum a-posteriori trajectory and effects at a given
intensity. The intensity is chosen by maximising the Laplace approximation of the
marginal likelihood (the window states integrated out, exact for linear-Gaussian
dynamics, the Kalman-smoother likelihood)::

    2 l(q) = -|r|^2 - |W c|^2 + 2 log|W| - log det(A_d^T A_d)

with ``A_d`` the window-state columns of the stacked Jacobian. The search runs DOWN a
grid of intensities, each fit warm-started from the previous one: a continuation from
nearly free windows (robust far from the optimum) to nearly one trajectory per segment
(the most precise), and stops where the data say the model no longer holds.

When nothing is unexplained the estimate sits at the bottom of the grid: the fit is the
output error over whole segments, at the Cramer-Rao bound. When something is, the
intensity is significant (likelihood-ratio test against the bottom of the grid, a 50:50
mixture of chi2(0) and chi2(1) since the null sits on the boundary, Self & Liang 1987),
the effects' standard errors widen as they must, and ``horizon_s`` says over what time
the Model can be trusted to predict to the noise.

A significant intensity may be judged again against a floor (:func:`intensity_floor`,
:func:`above_floor`): the intensity the replay's own integration error (step doubling of the
fit's defects) and the weights' noise over the longest segment explain. The null is then
``kappa <= floor``: the same one-sided test, against the likelihood at the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.measurement_noise import (
    estimate_measurement_noise,
    set_measurement_noise,
)
from airbearing.analysis.shooting.penalty import (  # noqa: F401 - also this module's names
    KAPPA_GRID,
    defect_whitening,
    hessian_pattern,
    penalised_solver,
    piece_durations,
    set_intensity,
    start_yaw_profiled,
)
from airbearing.analysis.shooting.sparse import (
    add_row_products,
    column_abs_sums,
    gram,
    gram_rows,
    release_free_memory,
)
from airbearing.errors import SolverError

__all__ = [
    "KAPPA_GRID",
    "Linearisation",
    "LinearisedFit",
    "ProcessNoise",
    "defect_whitening",
    "estimate_process_noise",
    "loglik",
    "peaked",
    "penalised_solver",
    "set_intensity",
]

#: Likelihood-ratio p-value below which the unexplained torque is significant.
SIGNIFICANCE = 1e-3


@dataclass(frozen=True)
class ProcessNoise:
    """The estimated unexplained torque of one fit.

    Attributes
    ----------
    intensity : float
        ``sigma_w``, rad/s per sqrt(s): the random-walk intensity of the rate (an
        unexplained torque of spectral density ``J sigma_w`` N m per sqrt(Hz)).
    kappa : float
        The same, dimensionless (defect variance over a piece, over the noise variance).
    lr : float
        Likelihood-ratio statistic against the bottom of the grid (no process noise).
    p : float
        Its p-value (chi2 mixture, module doc).
    significant : bool
        ``p < SIGNIFICANCE``.
    horizon_s : float
        s, time over which the unexplained torque moves the output by one noise sigma
        (``inf`` when not significant: whole segments).
    piece_s : float
        s, the mean length of the linked pieces.
    loglik : dict
        ``kappa -> log-likelihood`` of every intensity tried.
    """

    intensity: float
    kappa: float
    lr: float
    p: float
    significant: bool
    horizon_s: float
    piece_s: float
    loglik: dict

    def to_json(self) -> dict:
        """The JSON form (``fit.extra["process_noise"]``)."""
        return {
            "intensity": self.intensity,
            "unit": "rad/s/sqrt(s)",
            "kappa": self.kappa,
            "lr": self.lr,
            "p": self.p,
            "significant": self.significant,
            "horizon_s": self.horizon_s if math.isfinite(self.horizon_s) else None,
            "piece_s": self.piece_s,
        }


# ----------------------------------------------------------------------------
# the intensity


def loglik(problem, fit, k: int) -> float:
    """Laplace log marginal likelihood (module doc) of a fit at the problem's intensity.

    Parameters
    ----------
    problem : ShootingProblem
        The linked-window problem at the intensity the fit was made at.
    fit : Fit
        Its fit (``fit.extra["J"]``: the penalised residual's Jacobian).
    k : int
        Number of fitted effect parameters (the Jacobian's first ``k`` columns).

    Returns
    -------
    float
        The log marginal likelihood (nats; larger is better).
    """
    return _laplace(problem, fit.extra["J"], fit.rss, k, problem.penalty_logdet)


def _laplace(problem, J, rss: float, k: int, penalty_logdet: float) -> float:
    """:func:`loglik` of a residual ``rss`` and its Jacobian ``J`` (the defect rows whitened
    at the intensity whose ``log det W`` is ``penalty_logdet``)."""
    J = sp.csc_matrix(J)
    # the Gram matrix block of columns by block (sparse.gram): scipy's product copies J
    return _laplace_of(problem, gram(J if k == 0 else J[:, k:]), rss, penalty_logdet)


def _laplace_of(problem, G, rss: float, penalty_logdet: float) -> float:
    """:func:`_laplace` from the window states' Gram matrix ``G = J_d^T J_d``."""
    G = start_yaw_profiled(problem, sp.csc_matrix(G))
    # column scaling keeps the determinant well conditioned (its log is added back)
    c = np.sqrt(np.maximum(G.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    try:
        lu = splu(sp.csc_matrix(Dc @ G @ Dc))
        d = lu.U.diagonal()
        logdet = float(np.sum(np.log(np.abs(d)))) if np.all(d != 0) else np.inf
    except RuntimeError:  # singular: a state the data cannot fix at any intensity
        logdet = np.inf
    return float(
        -0.5 * rss + penalty_logdet + problem.meas_logdet - 0.5 * (logdet + 2 * np.log(c).sum())
    )


def estimate_process_noise(
    problem,
    p_base: np.ndarray,
    S: np.ndarray | None = None,
    theta0: np.ndarray | None = None,
    *,
    lower=None,
    upper=None,
    delta0=None,
    name: str = "process noise",
    grid=KAPPA_GRID,
    start=None,
    measurement: bool = True,
    stop_when_peaked: bool = False,
):
    """Fit at each intensity of ``grid`` (top down, warm-started) and keep the most likely.

    Parameters
    ----------
    problem : ShootingProblem
        On linked windows (:meth:`.WindowSet.linked`).
    p_base, S, theta0, lower, upper, delta0 :
        As :meth:`ShootingProblem.fit`.
    grid : sequence of float
        Dimensionless intensities, largest first.
    start : Fit, optional
        A fit at the top of the grid already made (saves one solve).
    measurement : bool
        First estimate an AR(1) model of coloured measurement noise on the top of the grid
        (:mod:`.measurement_noise`) when the problem has none yet; ``problem`` keeps it.
    stop_when_peaked : bool
        End the descent once the likelihood has clearly peaked (:func:`peaked`): the
        lower intensities, whose fits of a model that misses a torque are the costliest
        (long trajectories far from the data), are not fitted. The test's ``lr`` and the
        ``gap_whole`` are then those of the smallest intensity reached (``kappa_whole``);
        the most likely intensity, its fit and ``p`` are the same.

    Returns
    -------
    fit : Fit
        The fit at the most likely intensity; ``fit.extra["process_noise"]`` is the
        :class:`ProcessNoise`, and ``problem`` is left at that intensity.
    """
    # each fit starts where the last ended: its start's Jacobian is the last one's answer's
    problem.reuse_last = True
    try:
        return _estimate(problem, p_base, S, theta0, lower, upper, delta0, name, grid, start,
                         measurement, stop_when_peaked)  # fmt: skip
    finally:
        problem.reuse_last = False
        problem.forget_last()


def _estimate(
    problem, p_base, S, theta0, lower, upper, delta0, name, grid, start, measurement, stop
):
    """:func:`estimate_process_noise` (its arguments in order)."""
    k = 0 if S is None else np.asarray(S).shape[1]

    def fit_at(kappa, th, d):
        set_intensity(problem, kappa)
        # warm-started near the optimum: a converged objective ends the fit (OBJECTIVE_STOP)
        problem.objective_stop = True
        try:
            return problem.fit(
                p_base, S, th, lower=lower, upper=upper, delta0=d, name=f"{name} ({kappa:g})"
            )
        finally:
            problem.objective_stop = False

    if measurement and problem.measurement_noise is None:
        # coloured measurement noise first, on nearly free pieces (they absorb the slow part
        # of a trajectory error; measurement_noise's tests catch the rest), then the
        # intensity with the noise whitened
        if start is None:
            start = fit_at(grid[0], theta0, delta0)
        else:
            set_intensity(problem, grid[0])
        release_free_memory()  # (what the fits freed: the estimate's peak is on top of it)
        noise = estimate_measurement_noise(problem, start, k)
        release_free_memory()
        if noise is not None:
            set_measurement_noise(problem, noise)
            start = fit_at(grid[0], start.theta, start.delta)
    bounds = (np.asarray(p_base, dtype=float), S, lower, upper)
    fits = _descend(problem, fit_at, grid, theta0, delta0, start, k, bounds, stop)
    ll = {kappa: v[1] for kappa, v in fits.items()}
    fits = {kappa: v[0] for kappa, v in fits.items()}
    best = max(ll, key=ll.get)
    bottom = min(ll)  # the smallest intensity reached
    pn = _verdict(problem, ll, best, bottom)
    fit = fits[best]
    fit.extra["process_noise"] = {
        **pn.to_json(),
        # the gap of the most continuous fit reached (one trajectory per segment when the
        # continuation reached the bottom of the grid)
        "gap_whole": float(fits[bottom].gap),
        "kappa_whole": float(bottom),
        "gap_short": float(fits[max(fits)].gap),
        "loglik": pn.loglik,
    }
    noise = problem.measurement_noise
    fit.extra["measurement_noise"] = None if noise is None else noise.to_json()
    return fit


def _descend(problem, fit_at, grid, theta0, delta0, start, k: int, bounds, stop=False) -> dict:
    """``kappa -> (fit, log-likelihood)`` down the grid (warm-started), then one decade
    either side of the best; a solve that fails ends the descent (keeps what was found), and
    so does, with ``stop``, a likelihood that has clearly peaked (:func:`peaked`).

    An intensity's fit is the last IPOPT fit's Gauss-Newton linearisation solved at that
    intensity (:class:`Linearisation`, a :class:`LinearisedFit`) when that linearisation
    holds there; else an IPOPT fit from the last intensity's answer (the continuation),
    linearised in its turn. The decade either side of the best is tried on the best's own
    linearisation when the best is an IPOPT fit. The most likely intensity's fit is always
    IPOPT's (refitted from its point)."""
    out: dict = {}
    lin = None
    th, d = theta0, delta0

    def real(kappa, fit):
        nonlocal lin
        out[kappa] = (fit, loglik(problem, fit, k))
        lin = None  # (the last one freed before the next is made: each holds a Jacobian)
        release_free_memory()
        lin = Linearisation.of(problem, fit, k, bounds)
        _keep_best_jacobian(out, start)

    for i, kappa in enumerate(grid):
        if i == 0 and start is not None:
            set_intensity(problem, kappa)
            real(kappa, start)
        else:
            got = None if lin is None else lin.at(kappa)
            if got is not None:
                out[kappa] = got
            else:
                try:
                    real(kappa, fit_at(kappa, th, d))
                except SolverError:
                    if not out:
                        raise
                    break  # a lower intensity the fit cannot reach
        th, d = out[kappa][0].theta, out[kappa][0].delta
        if stop and peaked([out[a][1] for a in grid[: i + 1]]):
            break
    best = max(out, key=lambda a: out[a][1])
    if lin is not None and not isinstance(out[best][0], LinearisedFit):
        # a decade either side of the best from the best's linearisation, not the last
        # IPOPT fit's: when the best is far up the grid (a large unexplained torque) the
        # last is at its bottom, whose linearisation holds nowhere near the best
        lin = None  # (one linearisation held at a time: 100s of MB on an hour of samples)
        set_intensity(problem, best)
        lin = Linearisation.of(problem, out[best][0], k, bounds)
    for kappa in (best * 10.0, best / 10.0):
        if not (min(grid) < kappa < max(grid)) or kappa in out or len(out) < 2:
            continue
        got = None if lin is None else lin.at(kappa)
        if got is not None:
            out[kappa] = got
            continue
        near = out[min(out, key=lambda a, kappa=kappa: abs(math.log(a / kappa)))][0]
        try:
            real(kappa, fit_at(kappa, near.theta, near.delta))
        except SolverError:
            continue
    while isinstance(out[best := max(out, key=lambda a: out[a][1])][0], LinearisedFit):
        point = out.pop(best)[0]
        try:
            real(best, fit_at(best, point.theta, point.delta))
        except SolverError:  # (the start is IPOPT's: the loop ends)
            continue
    return out


#: nats: a log-likelihood this far below the best settles the test against it (module doc)
#: to double precision: its p-value ``0.5 chi2.sf(2 x 750, 1) = 0.5 erfc(sqrt(750))``, about
#: ``e^-750 / 97``, is below the smallest double (``e^-744.4``): 0, as any lower one would give.
PEAK_DROP = 750.0
#: Successive grid intensities (factors of 100 apart) at which the likelihood must fall.
PEAK_FALLS = 2


def peaked(lls) -> bool:
    """Whether a descent's log-likelihoods (nats, down the grid in order) have clearly peaked.

    True when the last :data:`PEAK_FALLS` intensities each fell below the one before and
    the last is more than :data:`PEAK_DROP` below the best: the best is significant
    against it at any level a double can state, and the likelihood (unimodal along the grid
    in practice: each lower intensity ties the pieces closer to one trajectory of a model
    that does not follow the data) keeps falling. A model that explains the data leaves a
    likelihood that flattens at the bottom of the grid: the descent goes on there.
    """
    lls = [float(v) for v in lls]
    if len(lls) < PEAK_FALLS + 1:
        return False
    tail = lls[-(PEAK_FALLS + 1) :]
    falling = all(b < a for a, b in zip(tail[:-1], tail[1:], strict=True))
    return falling and max(lls) - lls[-1] > PEAK_DROP


def _keep_best_jacobian(out: dict, start) -> None:
    """Drop the Jacobian of every IPOPT fit of the descent but the most likely so far (only
    its fit is returned; the others give their gap and likelihood): on an hour of 50 Hz samples
    each is about 150 MB. ``start`` is the caller's and keeps its own."""
    real = [a for a in out if not isinstance(out[a][0], LinearisedFit)]
    best = max(real, key=lambda a: out[a][1])  # the answer is the most likely IPOPT fit
    for kappa in real:
        fit = out[kappa][0]
        if kappa != best and fit is not start:
            fit.extra.pop("J", None)


#: An intensity's fit is taken from another intensity's linearisation (:class:`Linearisation`)
#: when one more step of it would lower the objective (half the sum of squares, noise
#: units) by less than this: about where the descent's IPOPT fits stop
#: (``solver.OBJECTIVE_STOP``, a scaled gradient of 1e-2).
LINEAR_TOL = 1e-4
#: Steps with the linearisation's Jacobian (the first its Gauss-Newton step, the next ones
#: corrections from the true residual) before IPOPT takes over.
CHORD_STEPS = 4


@dataclass(frozen=True)
class LinearisedFit:
    """The fit at one intensity from a linearisation: its answer and the gap it leaves."""

    theta: np.ndarray
    delta: np.ndarray
    rss: float
    gap: float


class Linearisation:
    """An IPOPT fit's Gauss-Newton linearisation, solved at other intensities.

    The measurement rows and the raw defects ``c`` (and their Jacobians) do not depend on
    the intensity; only the defects' whitening ``W`` does. At an intensity, the linearised
    problem ``min |r_m + J_m dz|^2 + |W (c + J_c dz)|^2`` is one sparse factorisation; its
    Gauss-Newton step is corrected with the residual evaluated at its answer (a chord
    method: the same Jacobian, no window Jacobian evaluated) until a step would lower the
    objective by less than :data:`LINEAR_TOL`. That point is the intensity's fit and its
    likelihood the Laplace one of the linearisation. Else (a step the linearisation does not
    hold over, an effect out of its bounds, a singular information) :meth:`at` gives None.
    """

    def __init__(self, problem, fit, k: int, bounds) -> None:
        J = sp.csc_matrix(fit.extra["J"])
        r = np.asarray(fit.extra["r"], dtype=float)
        n = problem.n_meas
        # the fit's Jacobian itself (no copy of its measurement rows: 100s of MB on an hour
        # of samples) and the Gram matrix of those rows, which no intensity changes
        self.J, self.n, self.rm = J, n, r[:n]
        self.Gm = gram_rows(J, n)
        C = sp.csc_matrix(fit.extra["linearised"][2])
        keep = column_abs_sums(J) > 0  # pinned states: zero columns
        self.C = C @ sp.diags(keep.astype(float))
        self.free = np.flatnonzero(keep)
        W0 = sp.csr_matrix(problem.penalty)
        unlinked = np.diff(W0.indptr) == 0
        self.c = splu(sp.csc_matrix(W0 + sp.diags(unlinked.astype(float)))).solve(r[n:])
        self.theta, self.delta = np.asarray(fit.theta, dtype=float), np.asarray(fit.delta)
        self.p_base, self.S = bounds[0], bounds[1]
        self.lower, self.upper = bounds[2], bounds[3]
        self.problem, self.k = problem, k

    @classmethod
    def of(cls, problem, fit, k: int, bounds):
        """The linearisation of ``fit`` (None when it keeps no Jacobian of its defects).

        Parameters
        ----------
        problem : ShootingProblem
            On linked windows, at the intensity ``fit`` was made at.
        fit : Fit
            An IPOPT fit of ``problem`` (its ``extra["J"]``, ``["r"]``, ``["linearised"]``).
        k : int
            Number of fitted effect parameters.
        bounds : tuple
            ``(p_base, S, lower, upper)`` as :meth:`ShootingProblem.fit` takes them.
        """
        if "J" not in fit.extra or "linearised" not in fit.extra or problem.penalty is None:
            return None
        return cls(problem, fit, k, bounds)

    def at(self, kappa: float):
        """``(LinearisedFit, log-likelihood)`` at ``kappa`` (``problem`` left at it), or None."""
        problem, k = self.problem, self.k
        set_intensity(problem, kappa)
        W = problem.penalty
        # the stacked Jacobian A = [J_m; W C] is never made (a copy of J_m, 100s of MB on an
        # hour of samples): its Gram matrix is J_m's carried on over the rows of W C, its
        # products are J_m's and W C's; the same sums in the same order as A's
        WC = W @ self.C
        G = add_row_products(self.Gm, WC)
        WC = sp.csc_matrix(WC)
        Gf = G if self.free.size == G.shape[1] else G[self.free][:, self.free]
        sc = np.sqrt(np.maximum(Gf.diagonal(), 1e-300))
        Ds = sp.diags(1.0 / sc)
        try:
            with np.errstate(all="ignore"):
                lu = splu(sp.csc_matrix(Ds @ Gf @ Ds))
        except RuntimeError:  # singular: IPOPT's to handle
            return None
        dz = np.zeros(G.shape[1])
        r = np.r_[self.rm, W @ self.c]  # the residual at the linearisation's point
        for i in range(CHORD_STEPS + 1):
            with np.errstate(all="ignore"):
                step = -lu.solve(self._rmatvec(WC, r)[self.free] / sc) / sc
                full = np.zeros(G.shape[1])
                full[self.free] = step
                y = self._matvec(WC, full)
                drop = 0.5 * float(np.sum(np.square(y, out=y)))
            if not np.isfinite(drop):
                return None
            if i and drop <= LINEAR_TOL:
                break
            if i == CHORD_STEPS:
                return None
            dz[self.free] += step
            theta = self.theta + dz[:k]
            if (self.lower is not None and np.any(theta < self.lower)) or (
                self.upper is not None and np.any(theta > self.upper)
            ):
                return None
            delta = self.delta + dz[k:].reshape(self.delta.shape, order="F")
            p = self.p_base + self.S @ theta if k else self.p_base
            with np.errstate(all="ignore"):
                r = problem.residual(delta, p)
            if not np.all(np.isfinite(r)):
                return None
        rss = float(r @ r)
        point = LinearisedFit(theta, delta, rss, problem.gap_of_residual(r))
        return point, _laplace_of(problem, G[k:, k:], rss, problem.penalty_logdet)

    def _rmatvec(self, WC: sp.csc_matrix, r: np.ndarray) -> np.ndarray:
        """``A^T r`` (``A = [J_m; W C]``): each column's sum over J_m's rows, carried on over
        W C's in turn (as scipy's ``A.T @ r``; the fit's own defect rows of ``J`` take a
        zero)."""
        n, J = self.n, self.J
        out = J.T @ np.r_[r[:n], np.zeros(J.shape[0] - n)]
        R = sp.csr_matrix(WC)
        rows = np.repeat(np.arange(R.shape[0]), np.diff(R.indptr))
        np.add.at(out, R.indices, R.data * r[n:][rows])
        return out

    def _matvec(self, WC: sp.csc_matrix, x: np.ndarray) -> np.ndarray:
        """``A x`` (``A = [J_m; W C]``, ``x`` zero off the free columns)."""
        y = self.J @ x
        if y.size != self.n + WC.shape[0]:  # pragma: no cover - J's defect rows are W C's
            return np.r_[y[: self.n], WC @ x]
        y[self.n :] = WC @ x  # (in place of the fit's own defect rows: no concatenation)
        return y


def _mixture_p(lr: float) -> float:
    """The p-value of a likelihood-ratio statistic ``lr`` under the 50:50 mixture of
    chi2(0) and chi2(1) (module doc)."""
    from scipy import stats  # (lazy: a light ``import airbearing``)

    return 0.5 * float(stats.chi2.sf(lr, 1)) if lr > 0 else 1.0


def _verdict(problem, ll: dict, best: float, bottom: float) -> ProcessNoise:
    """The :class:`ProcessNoise` of the most likely intensity (the problem is left at it)."""
    lr = max(0.0, 2.0 * (ll[best] - ll[bottom]))
    p = _mixture_p(lr)
    significant = p < SIGNIFICANCE
    set_intensity(problem, best)
    sigma_w = problem.process_noise[1]
    piece = float(np.mean(piece_durations(problem)[:-1])) if problem.windows.n > 1 else 0.0
    if significant and sigma_w > 0:
        if problem.attitude_measured:
            horizon = (3.0 * problem.sigma_att**2 / sigma_w**2) ** (1.0 / 3.0)
        else:
            horizon = problem.sigma_rate**2 / sigma_w**2
    else:
        horizon = math.inf
    return ProcessNoise(
        intensity=float(sigma_w),
        kappa=float(best),
        lr=float(lr),
        p=float(p),
        significant=bool(significant),
        horizon_s=float(horizon),
        piece_s=piece,
        loglik={float(a): float(b) for a, b in ll.items()},
    )
