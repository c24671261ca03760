"""Standard errors that survive coloured noise and model misfit, and the bound of the data.

Three numbers per fitted parameter:

``std_white``
    The white-noise Fisher value: the covariance of the fitted parameters, the window
    initial states eliminated (Schur complement), when each output group's residual is
    white with its own variance, the group's reduced chi-square (:func:`group_variances`).
    One chi-square pooled over the groups is wrong when their residuals stand at different
    levels of their weights: a noise-free attitude beside a noisy gyro, whose attitude
    residual is the integration's own error, halved the pooled chi-square and put the
    error at 0.71 of the bound. Right when the residual is white.
``std``
    The honest one: a sandwich (Huber-White) covariance ``B^-1 M B^-1`` whose meat ``M``
    is the heteroscedasticity-and-autocorrelation-consistent (HAC) long-run covariance of
    the residual scores within each segment, and never smaller than ``std_white`` (the
    sandwich is biased low in finite samples, and a white residual must not make an answer
    look more precise than its Fisher value) nor than ``crlb``. The meat is prewhitened
    (Andrews & Monahan 1992; :func:`prewhitened_scores`): per output group an AR(p) model
    of the residual (Yule-Walker, order by AIC, kept when it beats white noise in a
    likelihood-ratio test; ``statsmodels.tsa.stattools``, its autocovariances corrected for
    the fitted initial states, :meth:`.AR.yule_walker`) whitens each series, the scores'
    regressors pass through the inverse of the same filter (the recolouring is exact), and
    the whitened scores get a Bartlett-kernel HAC
    (``statsmodels.stats.sandwich_covariance.S_hac_simple``) whose bandwidth is the longest
    of Andrews' (1991) AR(1) plug-in (:func:`andrews_bandwidth`, as the CMG
    identification's sandwich), the Newey-West rule ``4 (n / 100)^(2/9)`` and three
    correlation times (the lag where the autocorrelation of the residual, or of the
    process-noise defects, falls below 1/e). A white residual (AR order 0) keeps the
    sandwich it had. The correlation-time rule alone was too short for white plus AR(1)
    noise: the white part pulls the autocorrelation below 1/e after a sample or two while a
    long memory remains (a spin-down's J_z under such gyro noise was covered in 36 of 40
    seeds, std 0.57 of the real spread). The process-noise defects' scores enter the same
    series, unfiltered, at their hand-over times (a torque correlated over several pieces,
    which the random walk of :mod:`.process_noise` does not describe). An in-model fit (the
    intensity at the bottom of the grid) takes its scores from the constrained problem, one
    trajectory per segment; a fit with an unexplained torque over enough pieces sums its
    scores per piece (:func:`_piece_meat`).
``crlb``
    The Cramer-Rao bound of the data: the Fisher information of ONE trajectory per segment
    (the windows' continuity enforced, one initial state per segment), not of free windows,
    at each output group's noise level: the smaller of the floor the problem's weights
    assume and the level of the group's own residual (the data show no more noise there:
    a floor from the data's differences can overstate it, and a noise-free attitude shows
    the integration's error only), never below the replay's resolution
    (:data:`RESOLUTION`). On free windows (a fixed window length asked for) there is no
    trajectory to join: NaN. Since every group's level is at most its residual's, ``std``
    is at least ``crlb`` (Gauss-Markov); only a group below the resolution can lift the
    bound above ``std_white``, and ``std`` then stays at the bound.

The scores are ``A_i r_i`` with ``A`` the parameters' Jacobian columns projected off the
nuisance columns (initial states), so the sandwich is the one of the profiled parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.autoregressive import AR
from airbearing.analysis.shooting.fit import (
    fit_jacobian,
    fit_jacobian_split,
    gram,
    information_inverse,
    solve_gram,
)
from airbearing.analysis.shooting.one_trajectory import _influence, _kkt_solve, _linearised
from airbearing.analysis.shooting.penalty import KAPPA_GRID, piece_durations
from airbearing.analysis.shooting.sparse import trailing_columns

__all__ = [
    "RESOLUTION",
    "HonestErrors",
    "Residuals",
    "andrews_bandwidth",
    "correlation_time",
    "crlb",
    "group_variances",
    "honest_errors",
    "normalised_residuals",
    "prewhitened_scores",
]

#: Autocorrelation below which two residual samples count as uncorrelated (1/e).
DECORRELATED = math.exp(-1.0)
#: Fewest linked pieces whose score sums give the long-run covariance (else per sample).
MIN_PIECES = 8
#: Largest AR(1) coefficient of the prewhitening (Andrews & Monahan's bound).
MAX_RHO = 0.97
#: rad/s, rad: the replay's resolution per output group, the smallest noise level a bound
#: is computed at (a noise-free log's residual is the integration's own error; the
#: discrepancy's weights never go below it either).
RESOLUTION = {"rate": 1e-7, "quat": 1e-6, "yaw": 1e-6, "ws": 1e-6}


@dataclass(frozen=True)
class HonestErrors:
    """Standard errors of a fit's first ``k`` parameters (module doc), SI units."""

    std: np.ndarray
    std_white: np.ndarray
    cov: np.ndarray
    cov_white: np.ndarray
    crlb: np.ndarray
    correlation_time_s: float
    nlags: int

    @property
    def efficiency(self) -> np.ndarray:
        """``std / crlb`` (1: the answer is as precise as the log allows)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.std / self.crlb


@dataclass(frozen=True)
class Residuals:
    """The primary output's normalised residual of one log segment, in time order."""

    source: int
    segment: int
    rows: np.ndarray  # (n,) log rows
    t: np.ndarray  # (n,) s from the segment's first usable row
    r: np.ndarray  # (n, n_axes), in noise units


def _segment_order(problem):
    """Per segment: the window samples in time order (usable rows only) and their times."""
    w = problem.windows
    seg = w.segments()
    L = w.length
    cum = np.concatenate([np.zeros((w.n, 1)), np.cumsum(w.dt, axis=1)], axis=1)
    end = (
        np.asarray(w.end, dtype=int)
        if w.end is not None
        else (w.weight > 0).shape[1] - 1 - np.argmax((w.weight > 0)[:, ::-1], axis=1)
    )
    out = []
    for s in np.unique(seg):
        idx, times = [], []
        t0 = 0.0
        for j in np.flatnonzero(seg == s):
            use = np.flatnonzero(w.weight[j] > 0)
            idx.append(j * L + use)
            times.append(t0 + cum[j, use])
            t0 += (
                cum[j, end[j]]
                if w.link is not None
                else cum[j, use[-1]] + float(np.median(w.dt[j, : max(use[-1], 1)]))
            )
        out.append((int(w.source[np.flatnonzero(seg == s)[0]]), int(s), np.concatenate(idx),
                    np.concatenate(times)))  # fmt: skip
    return out


def _series(problem):
    """Per output group, per segment and axis: residual rows in time order and their times."""
    cached = getattr(problem, "_noise_series", None)
    if cached is not None:
        return cached
    w = problem.windows
    L = w.length
    sizes = problem.group_sizes
    offsets, off = [], 0
    for o in problem.outputs:
        offsets.append(off)
        off += sizes[o] * L
    out: dict = {o: [] for o in problem.outputs}
    for _, _, idx, t in _segment_order(problem):
        j, s = idx // L, idx % L
        for g, o in enumerate(problem.outputs):
            for a in range(sizes[o]):
                rows = j * problem.n_win_res + offsets[g] + s * sizes[o] + a
                out[o].append((rows, np.asarray(t, dtype=float)))
    problem._noise_series = out
    return out


def normalised_residuals(problem, fit) -> list[Residuals]:
    """The primary output's residual (noise units) per log segment, in time order.

    Parameters
    ----------
    problem : ShootingProblem
    fit : Fit
        A fit of ``problem`` (its ``extra["r"]``).

    Returns
    -------
    list of Residuals
        One per segment: log rows, times (s from the segment's first row) and the
        residual ``(n, n_axes)`` of usable rows.
    """
    w = problem.windows
    r = np.asarray(fit.extra["r"])[: problem.n_meas]
    n_ax = (
        problem.n_rate
        if problem.outputs[0] == "rate"
        else (3 if problem.outputs[0] == "quat" else 1)
    )
    L = w.length
    per_win = r.reshape(w.n, problem.n_win_res)[:, : L * n_ax].reshape(w.n * L, n_ax)
    out = []
    for src, seg, idx, t in _segment_order(problem):
        out.append(Residuals(src, seg, w.rows.reshape(-1)[idx], t, per_win[idx]))
    return out


def _decorrelation_lag(series, max_lag: int) -> int:
    """The first lag at which the mean autocorrelation of ``series`` (1-D arrays, each
    weighted by its length; ``statsmodels.tsa.stattools.acf``) falls below 1/e."""
    # statsmodels: 0.7-2.1 s CPU to import, loaded only when this runs
    from statsmodels.tsa.stattools import acf

    acc, wsum = None, 0.0
    for x in series:
        n = x.size
        if not np.any(x != x[0]):
            continue
        c = acf(x, nlags=min(n // 2, max_lag), fft=True)
        acc = n * c if acc is None else acc[: c.size] + n * c[: acc.size]
        wsum += n
    if acc is None:
        return 0
    below = np.flatnonzero(acc / wsum < DECORRELATED)
    return int(below[0]) if below.size else acc.size


def correlation_time(residuals: list[Residuals], dt: float | None = None) -> float:
    """s, the lag at which the residuals' mean autocorrelation first falls below 1/e.

    The autocorrelation of each segment and axis (``statsmodels.tsa.stattools.acf``),
    averaged with the segments' lengths as weights; 0 for a white residual.
    """
    used = [res for res in residuals if res.r.shape[0] >= 8]
    lag = _decorrelation_lag([res.r[:, a] for res in used for a in range(res.r.shape[1])], 2000)
    step = [float(np.median(np.diff(res.t))) for res in used]
    h = dt if dt is not None else (float(np.median(step)) if step else 0.0)
    return float((lag - 1) * h) if lag > 1 else 0.0


def _defect_correlation_time(problem, d: np.ndarray) -> float:
    """s, the lag (in pieces, times their mean length) at which the whitened defects' mean
    autocorrelation within segments first falls below 1/e; 0 when they are independent."""
    w = problem.windows
    nd = problem.n_delta
    D = d.reshape(-1, nd)
    link = np.asarray(w.link, dtype=bool)
    seg = w.segments()[:-1]
    # a dof-1 gyro log's start yaw is held continuous, not a random walk (penalty.py)
    first = problem.n_att if problem.n_att and not problem.attitude_measured else 0
    series = []
    for sgm in np.unique(seg[link]):
        x = D[np.flatnonzero(link & (seg == sgm))]
        if x.shape[0] >= 4:
            series += [x[:, a] for a in range(first, nd)]
    lag = _decorrelation_lag(series, 20)
    return float(lag * np.mean(piece_durations(problem)[:-1])) if lag > 1 else 0.0


def _n_segments(problem) -> int:
    """Number of segments (trajectories) of the problem's windows."""
    return int(np.unique(problem.windows.segments()).size)


def _projected_of(fit, k: int) -> np.ndarray:
    """:func:`_projected` of ``fit``'s Jacobian, from the blocks it keeps when it keeps
    them (:func:`~airbearing.analysis.shooting.fit.fit_jacobian_split`: the whole matrix
    not made), else from the matrix."""
    N = fit.extra.get("N")
    split = None if N is not None else fit_jacobian_split(fit, k)
    if split is None:
        return _projected(fit_jacobian(fit), k, N)
    return _projected_split(*split)


def _projected(J, k: int, N=None) -> np.ndarray:
    """The parameters' Jacobian columns with the nuisance columns projected off (dense)."""
    if N is not None:
        J = sp.csc_matrix(J @ N) if not sp.issparse(J @ N) else (J @ N).tocsc()
    J = sp.csc_matrix(J)
    return _projected_split(J[:, :k].toarray(), trailing_columns(J, k))


def _projected_split(At: np.ndarray, An) -> np.ndarray:
    """:func:`_projected` of the parameters' columns ``At`` (dense) and the nuisance
    columns ``An`` (CSC)."""
    if An.shape[1] == 0:
        return At
    # scipy's sums, without its CSR copy of An (about J's size)
    G = gram(An)
    c = np.sqrt(np.maximum(G.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    B = np.asarray(An.T @ At)
    coef = solve_gram(Dc @ G @ Dc, B / c[:, None])
    return At - An @ (coef / c[:, None])


def group_variances(problem, r: np.ndarray, n_free: int) -> np.ndarray:
    """Variance of each output group's residual, (n_groups,) in noise units.

    The reduced chi-square of the group's usable rows (the free variables shared out over
    the groups by their numbers of rows), never below the replay's resolution
    (:data:`RESOLUTION`): a noise-free output's residual is the integration's own error.
    A residual with process-noise rows (beyond :attr:`n_meas`) gets one more entry, the
    defects' own.

    Parameters
    ----------
    problem : ShootingProblem
    r : ndarray
        The fit's residual (whitened measurement rows, then any defect rows).
    n_free : int
        Number of free variables of the fit (parameters and initial states).

    Returns
    -------
    ndarray
        ``rss_g / (n_g - n_free n_g / n)`` per group (1 for a group without rows).
    """
    r = np.asarray(r, dtype=float)
    rows, share = _free_shares(problem, r, n_free)
    n_meas = problem.n_meas
    rss = [
        float(r[:n_meas][sel] @ r[:n_meas][sel])
        for sel in ((problem.group == g) & problem.usable for g in range(len(problem.outputs)))
    ]
    floor = list(_resolution(problem))
    if r.size > n_meas:
        rss.append(float(r[n_meas:] @ r[n_meas:]))
        floor.append(0.0)
    dof = np.maximum(rows - share, 1.0)
    return np.where(rows > 0, np.maximum(np.asarray(rss) / dof, floor), 1.0)


def _free_shares(problem, r: np.ndarray, n_free: int):
    """``(rows, share)`` per output group (and the defects, when ``r`` has their rows): the
    usable rows and the free variables shared out over the groups by their numbers of rows."""
    rows = [int(np.sum((problem.group == g) & problem.usable)) for g in range(len(problem.outputs))]
    if r.size > problem.n_meas:
        rows.append(int(np.count_nonzero(r[problem.n_meas :])))
    rows = np.asarray(rows, dtype=float)
    return rows, n_free * rows / max(float(rows.sum()), 1.0)


def _resolution(problem) -> np.ndarray:
    """:data:`RESOLUTION` of each output group as a variance in the problem's noise units
    (at most 1: a weight at the resolution is a noise-free output)."""
    sigma = {"rate": problem.sigma_rate, "quat": problem.sigma_att, "yaw": problem.sigma_att,
             "ws": getattr(problem, "sigma_ws", None)}  # fmt: skip
    res = np.array([(RESOLUTION[o] / max(sigma[o], 1e-300)) ** 2 for o in problem.outputs])
    return np.minimum(res, 1.0)


def honest_errors(problem, fit, k: int) -> HonestErrors:
    """Sandwich (HAC) standard errors, white-noise ones and the bound (module doc).

    Parameters
    ----------
    problem : ShootingProblem
    fit : Fit
        A fit of ``problem`` whose first ``k`` free variables are the parameters.
    k : int
        Number of parameters.

    Returns
    -------
    HonestErrors
        ``std``, ``std_white``, ``crlb`` (k,) in the parameters' SI units, their
        covariances, the residuals' correlation time (s) and the HAC bandwidth (samples).
    """
    # statsmodels: 0.7-2.1 s CPU to import, loaded only when this runs
    from statsmodels.stats.sandwich_covariance import S_hac_simple

    fit_std = np.asarray(fit.theta_std[:k], dtype=float)
    residuals = normalised_residuals(problem, fit)
    tau = correlation_time(residuals)
    if k == 0:
        z = np.zeros(0)
        return HonestErrors(z, z, np.zeros((0, 0)), np.zeros((0, 0)), z, tau, 0)
    r = np.asarray(fit.extra["r"])
    n_meas = problem.n_meas
    pn = fit.extra.get("process_noise") or {}
    lin = _linearised(problem, fit, k)
    con = None if lin is None else _kkt_solve(*lin, k)
    # in-model (the intensity at the bottom of the grid): the fit is one trajectory per
    # segment, and its errors are those of the constrained problem (the stiff penalties of
    # the bottom intensity make the stacked Gram matrix lose the parameters' information)
    # (a fit without its own estimate, e.g. one log alone at the joint intensity, is in-model
    # when that intensity is the bottom of the grid)
    kappa = problem.process_noise[0] if problem.process_noise else None
    in_model = (not pn["significant"]) if pn else (kappa is not None and kappa <= KAPPA_GRID[-1])
    whole = con is not None and problem.penalty is not None and in_model
    group = np.r_[problem.group, np.full(r.size - n_meas, len(problem.outputs))]
    # the free variables the residual lost: one initial state per segment in-model
    n_free = k + problem.n_delta * _n_segments(problem) if whole else fit.n_free
    r_fit = r[:n_meas] if whole else r  # in-model, the defects are no part of the model
    s2 = group_variances(problem, r_fit, n_free)
    bound = np.full(k, np.nan)
    if con is not None:
        level = np.minimum(s2[: len(problem.outputs)], 1.0)  # never above the floor
        cov_b = con[0] if np.all(level == 1.0) else _kkt_solve(*lin, k, level[problem.group])[0]
        bound = np.sqrt(np.maximum(np.diag(cov_b), 0.0))
    # the measurement Jacobian (about the size of the fit's) let go before the projected
    # columns are made: on an hour of 50 Hz three-axis samples both at once were the
    # honest errors' peak
    M = _influence(lin[0], lin[2], con, k) if whole else None
    del lin, con
    if whole:
        # theta - theta_true ~ -M r: per group, its rows' share at the group's variance
        cov_w = (M * s2[problem.group][None, :]) @ M.T
        G = np.vstack([M.T, np.zeros((r.size - n_meas, k))])
        A = None
    else:
        A = G = _projected_of(fit, k)
        Binv = _bread_inverse(A)
        cov_w = Binv @ ((A * s2[group][:, None]).T @ A) @ Binv
    cov_w = 0.5 * (cov_w + cov_w.T)
    var = np.diag(cov_w)
    # not identifiable: the fit's own verdict on its Gram matrix, except in-model, where the
    # constrained problem decides (its stiff penalties are what the Gram matrix loses)
    ok = (var > 0) & (whole | np.isfinite(fit_std))
    std_w = np.where(ok, np.sqrt(np.abs(var)), np.nan)
    bound = np.where(bound > 0, bound, np.nan)
    w = problem.windows
    if not whole and r.size > n_meas and w.link is not None:
        pw = _piece_meat(problem, A * r[:, None])
        if pw is not None:  # an unexplained torque: scores summed per piece, prewhitened
            meat, rho, nl = pw
            tau = max(tau, _defect_correlation_time(problem, r[n_meas:]))
            return _sandwich(A, meat, std_w, cov_w, bound, tau, nl)
    free = _free_shares(problem, r_fit, n_free)[1]
    scores, _ = prewhitened_scores(problem, G[:n_meas], r[:n_meas], free)
    per_sample = np.zeros((w.n * w.length, k))
    np.add.at(per_sample, problem.sample, scores)
    dt = float(np.median(w.dt[w.weight[:, 1:] > 0]))
    if r.size > n_meas and w.link is not None and not whole:
        # process-noise rows: each pair's whitened defect belongs to its hand-over time (the
        # next window's first sample), so a torque the random walk does not describe (one
        # correlated over several pieces) widens the errors through the same HAC sum
        nd = problem.n_delta
        pair = np.arange(r.size - n_meas) // nd
        np.add.at(per_sample, (pair + 1) * w.length, G[n_meas:] * r[n_meas:, None])
        tau = max(tau, _defect_correlation_time(problem, r[n_meas:]))
    order = _segment_order(problem)
    shortest = min(len(o[2]) for o in order)
    meat = np.zeros((k, k))
    lags = []
    for _, _, idx, _ in order:
        x = per_sample[idx]
        n = x.shape[0]
        newey_west = int(math.floor(4 * (n / 100.0) ** (2.0 / 9.0)))
        nl = max(newey_west, andrews_bandwidth(x), int(math.ceil(3 * tau / dt)))
        nl = max(0, min(nl, shortest // 2, n - 1))
        lags.append(nl)
        meat = meat + S_hac_simple(x, nlags=nl)
    return _sandwich(A, meat, std_w, cov_w, bound, tau, int(max(lags) if lags else 0))


def _bread_inverse(A: np.ndarray) -> np.ndarray:
    """``(A'A)^+`` column-scaled (the bread of the sandwich)."""
    return information_inverse(A.T @ A)[0]


def andrews_bandwidth(scores: np.ndarray) -> int:
    """Bartlett-kernel bandwidth (lags) of Andrews (1991) with his AR(1) plug-in, the score
    columns weighted equally; at most ``n - 1``.

    Parameters
    ----------
    scores : ndarray (n, k)
        A score series in time order.

    Returns
    -------
    int
        ``floor(1.1447 (alpha(1) n)^(1/3))``, Andrews' eq. (6.4) for the Bartlett kernel.
    """
    n = scores.shape[0]
    if n < 3:
        return 0
    num = den = 0.0
    for x in scores.T:
        d = float(x[:-1] @ x[:-1])
        if d <= 0:
            continue
        rho = float(np.clip((x[1:] @ x[:-1]) / d, -MAX_RHO, MAX_RHO))
        s4 = float(np.mean((x[1:] - rho * x[:-1]) ** 2)) ** 2
        num += 4.0 * rho**2 * s4 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += s4 / (1 - rho) ** 4
    if den <= 0:
        return 0
    return int(min(np.floor(1.1447 * (num / den * n) ** (1.0 / 3.0)), n - 1))


def prewhitened_scores(problem, G: np.ndarray, r: np.ndarray, free=None):
    """The measurement rows' scores ``G_i r_i`` prewhitened (module doc): ``(scores, phi)``.

    Per output group, an AR(p) model of the residual pooled over segments and axes
    (:meth:`.AR.yule_walker`, the longest order tried Schwert's ``12 (n / 100)^(1/4)``);
    each series (one segment, one axis, usable rows in time order; a hole left by an
    outlier is closed) is filtered by it, ``u = Phi(L) r``, and its regressors backwards by
    the inverse, ``Z = Phi(L)^-T G``, so that ``sum_i G_i r_i = sum_i Z_i u_i`` exactly.

    Parameters
    ----------
    problem : ShootingProblem
    G : ndarray (n_meas, k)
        Per measurement row, the parameters' regressor (projected Jacobian row, or the
        influence column of the constrained problem).
    r : ndarray (n_meas,)
        The measurement residual (noise units).
    free : sequence of float, optional
        Per output group, the free variables fitted to its rows (:meth:`.AR.yule_walker`
        corrects its autocovariances for them; default none).

    Returns
    -------
    scores : ndarray (n_meas, k)
        ``Z_i u_i`` in the residual's row order (0 on rows of no series).
    phi : dict
        ``group -> AR coefficients`` (empty: white).
    """
    scores = G * r[:, None]
    phis = {}
    for g, (group, series) in enumerate(_series(problem).items()):
        series = [rows for rows, _ in series if rows.size]
        if not series:
            continue
        n_all = sum(rows.size for rows in series)
        maxlag = int(min(12 * (n_all / 100.0) ** 0.25, max(rows.size for rows in series) // 2))
        model = AR.yule_walker(
            [r[rows] for rows in series], maxlag, 0.0 if free is None else float(free[g])
        )
        phis[group] = model.phi
        if model.order == 0:
            continue
        for rows in series:
            scores[rows] = model.recolour_t(G[rows]) * model.whiten(r[rows])[:, None]
    return scores, phis


def _sandwich(A, meat, std_w, cov_w, bound, tau: float, nlags: int) -> HonestErrors:
    """``B^-1 M B^-1`` with ``B = A'A`` (``A`` None: ``meat`` is the covariance already),
    never below the white-noise errors nor the bound."""
    if A is None:
        cov = meat
    else:
        Binv = _bread_inverse(A)
        cov = Binv @ meat @ Binv
    cov = 0.5 * (cov + cov.T)
    std_hac = np.sqrt(np.maximum(np.diag(cov), 0.0))
    ok = np.isfinite(std_w)
    floor = np.maximum(np.where(ok, std_w, 0.0), np.where(np.isfinite(bound), bound, 0.0))
    std = np.where(ok, np.maximum(std_hac, floor), np.nan)
    return HonestErrors(
        std=std,
        std_white=std_w,
        cov=cov,
        cov_white=cov_w,
        crlb=bound,
        correlation_time_s=tau,
        nlags=int(nlags),
    )


def _piece_meat(problem, scores: np.ndarray):
    """``(meat, rho, nlags)``: the long-run covariance of the scores summed per piece
    (module doc), or None with too few pieces to estimate it (fewer than
    :data:`MIN_PIECES`).

    A piece's sum holds every correlation within it exactly; between pieces the series of
    each segment is prewhitened by one AR(1) coefficient ``rho`` pooled over segments and
    parameters (each standardised), its Newey-West HAC taken, and recoloured by
    ``1 / (1 - rho)^2`` (Andrews & Monahan 1992): a torque correlated over several pieces
    makes the sums persistent, and a kernel alone, over a few pieces, misses most of it.
    """
    # statsmodels: 0.7-2.1 s CPU to import, loaded only when this runs
    from statsmodels.stats.sandwich_covariance import S_hac_simple

    w = problem.windows
    n_meas, nd = problem.n_meas, problem.n_delta
    if w.n < MIN_PIECES:
        return None
    piece = np.empty(scores.shape[0], dtype=int)
    piece[:n_meas] = np.arange(n_meas) // problem.n_win_res
    # a pair's defect belongs to the later piece (its hand-over is that piece's first row)
    piece[n_meas:] = np.minimum(np.arange(scores.shape[0] - n_meas) // nd + 1, w.n - 1)
    sums = np.zeros((w.n, scores.shape[1]))
    np.add.at(sums, piece, scores)
    seg = w.segments()
    series = [sums[seg == s] for s in np.unique(seg)]
    sd = np.where(sums.std(axis=0) > 0, sums.std(axis=0), 1.0)
    num = sum(float(np.sum((x[1:] / sd) * (x[:-1] / sd))) for x in series if len(x) > 1)
    den = sum(float(np.sum((x[:-1] / sd) ** 2)) for x in series if len(x) > 1)
    rho = float(np.clip(num / den, 0.0, MAX_RHO)) if den > 0 else 0.0
    meat = np.zeros((scores.shape[1], scores.shape[1]))
    lags = []
    for x in series:
        e = np.vstack([x[:1], x[1:] - rho * x[:-1]])
        n = e.shape[0]
        nl = max(0, min(int(math.floor(4 * (n / 100.0) ** (2.0 / 9.0))), n - 1))
        lags.append(nl)
        meat = meat + S_hac_simple(e, nlags=nl)
    return meat / (1.0 - rho) ** 2, rho, max(lags) if lags else 0


def crlb(problem, fit, k: int) -> np.ndarray:
    """The Cramer-Rao bound (1-sigma, SI) of the first ``k`` parameters (module doc).

    The measurement Jacobian at ``fit`` restricted to the directions that keep every linked
    pair of windows continuous (one trajectory per segment), each output group at the
    smaller of its weights' floor and its residual's level (never below
    :data:`RESOLUTION`): :attr:`HonestErrors.crlb`. NaN on free windows (no trajectory to
    join) and where the data cannot identify a parameter.
    """
    if k == 0:
        return np.zeros(0)
    return honest_errors(problem, fit, k).crlb
