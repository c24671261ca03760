"""A slow torque about a steady axis, as a nuisance the fit tests and marginalises.

A platform spinning about a nearly constant axis makes a friction or drag about that
axis a nearly constant torque (:func:`.confounding.constant_torque_confounding`), and a
torque the Model does not hold that varies slowly against the log (a bearing's air-flow
torque, a drift correlated over tens of seconds) is nearly constant over it too. The
named effect then takes that torque's mean: its value is biased by ``mean(tau) /
rate``, and no covariance of the residual sees a bias.

Here the slow torque is a nuisance: on each steady axis and log segment, a torque
``tau(t) = a + b t + x(t)``: a constant and a linear drift (free; Legendre polynomials on
the segment) and an Ornstein-Uhlenbeck torque ``x`` (``dx = -x / T dt + s dW``) whose
correlation time ``T`` and level ``q = s sqrt(T / 2)`` are estimated
(:mod:`.ou_torque`). The torque is linear between knots: each window (piece) cut into
``K`` equal intervals, at least :data:`KNOTS_PER_SEGMENT` per segment. Its columns of the
weighted residual's Jacobian are exact: CasADi's forward derivative of the shooting
problem's residual function in its data, along the Model's disturbance-torque input
``tau_<axis>`` shaped as each knot's hat function, ``K + 1`` directions per axis (every
window's rows are its own, so one direction gives every window's response), at the fitted
parameters and window states. That function is built without the compiled C sample step
(its library carries derivatives in the states and parameters only, not in an input) and
evaluated once, by CasADi's virtual machine.
Linearised at the fit (one Gauss-Newton step, the shooting problem's own weighting,
process-noise defects included; the window states projected off through the Gram matrix,
linear in the samples), the nuisance is

- **tested**: an F test (``scipy.stats.f``) of the residual sum of squares the constant and
  drift take, over their ``m`` columns, against the fit's residual variance (robust to a
  noise level off by a few per cent, as a chi-square test would not be), never below the
  level the residual is weighted at (a noise-free log's residual, the integration's own
  error below the replay's resolution, is no noise to test against);
- **estimated**: ``T`` and ``q`` by restricted maximum likelihood (the named parameters and
  the trend integrated out flat, the OU knots as Gaussian with their tridiagonal
  precision), ``T`` between the knot spacing (below it the torque is the white process
  noise's) and :data:`OU_T_MAX_SPANS` times the longest segment (beyond it the trend holds
  it); a level at its lower bound leaves the constant and drift alone;
- **marginalised** when the test says it is there, or when the process noise already says
  an unexplained torque acts (its slow part about the steady axis is then what a named
  effect about that axis cannot be told from, seen or not by the test): the named
  parameters move to their posterior mean with the OU prior (generalised least squares:
  the bias of the slow torque removed) and their errors become the posterior ones,
  ``sqrt(C_jj)``, narrower or wider than the fit's honest (sandwich) error: the factor is
  their ratio, never the posterior's growth over the Fisher value applied on top of the
  sandwich, which counted the slow torque twice (in the sandwich's meat and in the
  information lost to it); mean and variance mixed over ``T`` and ``q``
  (:func:`.ou_torque.integrated_posterior`: their uncertainty counted, not taken as known
  at the maximum).

A friction about the steady axis is then known only from how its torque follows the
rate's small changes (nutation) and from the other axes, which is all a log can say when
a slow torque is present. Where neither the test nor the process noise finds an
unexplained torque, nothing changes: the nuisance costs the answer nothing where it is
absent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.discrepancy.honest import honest
from airbearing.analysis.discrepancy.ou_torque import fit_ou
from airbearing.analysis.discrepancy.slow_torque_basis import (
    AXES,
    MAX_OU_KNOTS,
    coarsen,
    knot_columns,
    trend_values,
)
from airbearing.analysis.shooting.fit import fit_jacobian, gram, solve_gram
from airbearing.analysis.shooting.sparse import trailing_columns

__all__ = [
    "MAX_FACTOR",
    "SLOW_TORQUE_P",
    "SLOW_TORQUE_ORDER",
    "SlowTorque",
    "slow_torque",
]

#: p-value of the F test below which the slow torque is fitted as a nuisance (the
#: coloured-noise model's level: a false alarm widens one run's errors in a thousand).
SLOW_TORQUE_P = 1e-3
#: Highest Legendre order in time of the free trend per axis and segment: a constant and
#: a linear drift (a torque correlated over longer than the log is mostly these).
SLOW_TORQUE_ORDER = 1
#: Largest growth of a named parameter's error with the trend free for which the
#: nuisance is fitted. Beyond it the named effect's torque lies within 1e-4 (sine of the
#: angle) of the trend's span over the logs: it is the slow torque itself up to details
#: of its form (a Coulomb friction on a coast-down that never reverses: its smoothed sign,
#: a factor of about 1.4e5), and the joint step along it is set by those details, not by
#: the data. A per-axis z friction of seed 004's spinning platform keeps 1/50 to 1/130 of
#: its information (the nutation) and is fitted.
MAX_FACTOR = 1e4
#: Widest two-standard-error interval of the correlation time (high over low) that the
#: verdict calls an estimate; wider, it says the logs do not resolve it (a 30 s log of a
#: 20 s torque: the interval spans orders of magnitude).
RESOLVED_RATIO = 100.0
#: Upper bound of the correlation time, in spans of the longest segment.
OU_T_MAX_SPANS = 10.0
#: Why the OU part is not fitted when the named effects' posterior with the knots is not
#: positive definite in floating point (nearly confounded frictions on a narrow speed range).
NOT_POSITIVE_DEFINITE = (
    "the named effects are too nearly confounded with one another (their posterior with "
    "the knots is not positive definite in floating point)"
)


@dataclass(frozen=True, eq=False)
class SlowTorque:
    """The slow-torque nuisance at a fit.

    Attributes
    ----------
    axes : tuple of str
        The steady axes it acts on (``"z"`` ...).
    order : int
        Highest Legendre order in time of the free trend per axis and segment.
    n_columns : int
        Trend parameters (axes times segments times ``order + 1``), the F test's.
    statistic : float
        The F statistic of the residual sum of squares the trend takes.
    p : float
        Its p-value (``scipy.stats.f``, ``n_columns`` and the fit's residual degrees of
        freedom).
    significant : bool
        ``p < SLOW_TORQUE_P``.
    coefficients : ndarray
        The trend's Legendre coefficients, N m (axis, segment, order, in that nesting).
    step : ndarray (k,)
        Change of the named parameters when the nuisance is fitted jointly (the posterior
        mean with the OU prior).
    factor : ndarray (k,)
        What each named parameter's honest standard error is multiplied by with the
        nuisance. With the OU part fitted: :attr:`posterior_factor`, so the product is the
        posterior std alone (below 1 where the sandwich is the wider: the coverage study's
        x and y frictions with a gyro; docs, honest answers). With the constant and drift
        alone: the growth of the error in the fit's Fisher information (>= 1).
    identifiable : bool
        Every factor with the trend free at most :data:`MAX_FACTOR`: no named parameter is
        (nearly) the nuisance itself. A Coulomb friction on a coast-down that never reverses
        is exactly a constant torque; beside the nuisance it has no information left, and
        the joint step along that direction is arbitrary, so the nuisance is not fitted then.
    torque_means : ndarray or None
        The fitted mean torque (N m) per axis and segment over its knots.
    ou : OUFit or None
        The OU part (:class:`.ou_torque.OUFit`): correlation time and level.
    ou_skipped : str or None
        Why the OU part was not fitted (the constant and drift's answer stands), in words;
        None when it was fitted (or not asked: no named parameter identifiable).
    std : ndarray (k,) or None
        The named parameters' posterior std with the OU part fitted (mixed over ``T`` and
        ``q``), in their own units; None without it.
    posterior_factor : ndarray (k,) or None
        With the OU part fitted, ``std`` over the fit's honest (sandwich) std: what the
        honest std is multiplied by to be the posterior's alone (below 1 where the sandwich
        already held the slow torque, as it does on x and y with a gyro); None without it.
    """

    axes: tuple
    order: int
    n_columns: int
    statistic: float
    p: float
    significant: bool
    coefficients: np.ndarray
    step: np.ndarray
    factor: np.ndarray
    identifiable: bool = True
    torque_means: np.ndarray | None = None
    ou: object = None
    ou_skipped: str | None = None
    std: np.ndarray | None = None
    posterior_factor: np.ndarray | None = None

    def correlation_time(self) -> tuple[float, tuple[float, float]] | None:
        """``(T, (low, high))`` s: the estimate and its two-standard-error interval in
        ``log T``; None without an OU part (its level at the lower bound)."""
        if self.ou is None or self.ou.at_lower:
            return None
        s = self.ou.log_T_std
        with np.errstate(over="ignore"):  # T not resolved: the interval is (0, inf)
            return self.ou.T, (self.ou.T * np.exp(-2 * s), self.ou.T * np.exp(2 * s))

    def to_json(self) -> dict:
        out = {
            "axes": list(self.axes),
            "order": int(self.order),
            "F": float(self.statistic),
            "p": float(self.p),
            "significant": bool(self.significant),
            "torque_mean": [float(x) for x in self.means()],
        }
        ct = self.correlation_time()
        out["correlation_time_s"] = None if ct is None else float(ct[0])
        out["correlation_time_interval_s"] = (
            None if ct is None or not np.all(np.isfinite(ct[1])) else [float(x) for x in ct[1]]
        )
        out["level"] = None if ct is None else float(self.ou.q)
        out["ou"] = "not fitted" if self.ou_skipped is not None else "fitted"
        out["ou_reason"] = self.ou_skipped
        return out

    def means(self) -> np.ndarray:
        """The fitted mean torque (N m) per axis and segment."""
        if self.torque_means is not None:
            return np.asarray(self.torque_means)
        return np.asarray(self.coefficients)[:: self.order + 1]

    def words(self) -> str:
        """One phrase for the verdict."""
        ax = ", ".join(self.axes)
        trend = "a constant" + (" and a linear drift" if self.order >= 1 else "")
        ct = self.correlation_time()
        skipped = ""
        if self.ou_skipped is not None:  # said: the errors hold no faster variation then
            over = ""
            form = f"{trend} per segment"
            skipped = (
                f"; the Ornstein-Uhlenbeck part of the slow torque is not fitted "
                f"({self.ou_skipped}), so the value and error hold only its constant and "
                "drift, none of its faster variation"
            )
        elif ct is None:
            over = ""
            form = f"{trend} per segment (no faster variation found)"
        else:
            lo, hi = ct[1]
            level = f"level {self.ou.q:.2g} N m"
            if hi / lo <= RESOLVED_RATIO:
                over = f", correlated over ~{ct[0]:.2g} s ({lo:.2g}-{hi:.2g} s; {level}),"
            else:
                over = (
                    f", correlated over a time these logs do not resolve (likeliest "
                    f"~{ct[0]:.2g} s; {level}),"
                )
            form = f"{trend} per segment and an Ornstein-Uhlenbeck torque"
        mean = ", ".join(f"{m:.2g}" for m in self.means())
        if self.significant:
            return (
                f"a slow torque about {ax}{over} is significant (F test p {self.p:.2g}; "
                f"{form}, mean {mean} N m): the value and error are with it fitted{skipped}"
            )
        return (
            f"an unexplained torque is significant, so its slow part about {ax}{over} "
            f"({form}, mean {mean} N m; F test p {self.p:.2g} alone) is fitted with the "
            f"named effects: the value and error are with it{skipped}"
        )


def slow_torque(problem, fit, datas, axes, *, order: int = SLOW_TORQUE_ORDER, honest_std=None):
    """The slow-torque nuisance on the steady ``axes`` at ``fit`` (module doc).

    Parameters
    ----------
    problem : ShootingProblem
        The problem ``fit`` was made on (its weighting, process noise and whitening).
    fit : Fit
        The named effects' fit (the first ``k`` parameters the named ones).
    datas : sequence of ReplayData
        The logs (their times).
    axes : sequence of int
        Steady body axes (:func:`.confounding.steady_axes`).
    order : int
        Highest Legendre order in time of the free trend (0 or 1).
    honest_std : ndarray (k,), optional
        The named parameters' honest errors the caller reports (their units; with the
        noise-free floor of :func:`.honest.honest` where it applies), which the factor
        multiplies; None: :func:`.honest.honest` of the fit, without that floor.

    Returns
    -------
    SlowTorque or None
        None when it cannot be formed: no axis, no parameter, a fit under hard continuity
        constraints (its window states move together with a torque), no ``tau`` input.
    """
    k = len(fit.theta)
    if not len(axes) or k == 0 or "N" in fit.extra or "r" not in fit.extra:
        return None
    cols = knot_columns(problem, fit, datas, axes)
    if cols is None:
        return None
    # a segment no window covers (a short piece between glitches) has no knots: no block
    # (as the constant and drift are formed only on segments with windows)
    blocks = [b for b in cols[1] if b.size]
    if not blocks:
        return None
    G, blocks = coarsen(cols[0], blocks, MAX_OU_KNOTS)
    r = np.asarray(fit.extra["r"], dtype=float)
    J = sp.csc_matrix(fit_jacobian(fit))
    if J.shape[0] != r.size or G.shape[0] != r.size or not np.all(np.isfinite(G.data)):
        return None
    Lt = trend_values(blocks, order)
    n_t = Lt.shape[1]
    dof = fit.n_res - fit.n_free - n_t
    if dof <= 0:
        return None
    # the Gram matrix of [J_theta, G, r] with the window states projected off, and of the
    # named parameters with the trend: [J_theta, G Lt, r]
    H = _projected_gram(J, k, G, r)
    m = G.shape[1]
    E = np.zeros((k + m + 1, k + n_t + 1))
    E[:k, :k] = np.eye(k)
    E[k : k + m, k : k + n_t] = Lt
    E[-1, -1] = 1.0
    Ht = E.T @ H @ E
    scale = np.sqrt(np.diag(Ht)[:-1])
    if np.any(scale == 0):
        return None
    D = np.r_[1.0 / scale, 1.0]
    Hs = Ht * D[:, None] * D[None, :]
    info, b = Hs[:-1, :-1], -Hs[:-1, -1]
    coef = _solve_psd(info, b)
    coef0 = _solve_psd(info[:k, :k], b[:k])
    rss = float(r @ r)
    taken = float(b @ coef - b[:k] @ coef0)
    from scipy import stats  # here: the search modules do not import scipy.stats

    # the residual's variance, never below the level its weights assume (1: at the noise
    # floor): a noise-free log's residual is the integration's own error, not noise
    F = (max(taken, 0.0) / n_t) / max((rss - taken) / dof, 1.0)
    p = float(stats.f.sf(F, n_t, dof))
    with np.errstate(invalid="ignore", divide="ignore"):
        factor_trend = np.sqrt(_inverse_diagonal(info)[:k] / _inverse_diagonal(info[:k, :k]))
    factor_trend = np.where(np.isfinite(factor_trend), np.maximum(factor_trend, 1.0), 1.0)
    identifiable = bool(np.max(factor_trend) <= MAX_FACTOR)
    trend_coef = coef[k:] / scale[k:]
    ou, skipped = None, None
    step = (coef[:k] - coef0) / scale[:k]
    factor = factor_trend
    if identifiable:
        ou, skipped = _fit_ou(H, k, G, Lt, blocks, rss, taken, fit, problem)
    post, posterior_factor = None, None
    if ou is not None:
        # The named error becomes the OU posterior's alone: the factor is its std over the
        # fit's honest (sandwich) std, which the caller multiplies. The sandwich is the
        # spread of the fit's own estimate with the slow torque left in the residual (its
        # meat holds the torque's correlated scores); the posterior is the covariance of
        # the estimate reported, the posterior mean, with the torque a term of the model
        # (its residual white at sigma2 by construction: the level of the residual with
        # every knot free). Before, the factor was the posterior over the white Fisher
        # value and multiplied the sandwich: the slow torque counted twice, once in the
        # sandwich's meat and once in the posterior's information lost to it (std 13-550
        # times the real spread on the coverage study's cases (c) and (d) with a gyro).
        # The posterior alone may narrow the sandwich too: it kept the truth within 3 std
        # wherever the sandwich did on the study's seeds 0-19 and brought every value's
        # std closer to its spread (docs, honest answers: "the slow torque's errors,
        # counted once").
        post = np.sqrt(np.maximum(np.diag(ou.cov_beta)[:k], 0.0))
        sandwich = (
            _honest_std(problem, fit, k)
            if honest_std is None
            else np.asarray(honest_std, dtype=float)[:k]
        )
        base_var = _inverse_diagonal(info[:k, :k]) / scale[:k] ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            f_ou = np.sqrt(np.diag(ou.cov_beta)[:k] / ou.sigma2 / base_var)
            f_post = post / sandwich
        ok = np.isfinite(f_post) & (f_post > 0)
        f_old = np.where(np.isfinite(f_ou), np.maximum(f_ou, 1.0), factor_trend)
        posterior_factor = np.where(ok, f_post, f_old)
        factor = posterior_factor
        step = -ou.beta[:k] - coef0 / scale[:k]
        trend_coef = -ou.beta[k : k + n_t]
    means = _means(blocks, Lt, trend_coef, None if ou is None else -ou.x)
    return SlowTorque(
        axes=tuple(AXES[a] if problem.model.dof == 3 else "z" for a in axes),
        order=int(order),
        n_columns=int(n_t),
        statistic=float(F),
        p=p,
        significant=bool(p < SLOW_TORQUE_P),
        coefficients=trend_coef,
        step=step,
        factor=factor,
        identifiable=identifiable,
        torque_means=means,
        ou=None if ou is None else ou.ou,
        ou_skipped=skipped,
        std=post,
        posterior_factor=posterior_factor,
    )


def _honest_std(problem, fit, k: int) -> np.ndarray:
    """The fit's honest (sandwich) std of its first ``k`` parameters (:func:`.honest.honest`,
    without its noise-free floor), for a caller that does not pass the errors it multiplies
    by the factor (the search passes its own); NaN where it gives none."""
    try:
        return np.asarray(honest(problem, fit, k).std, dtype=float)
    except (np.linalg.LinAlgError, ValueError):
        return np.full(k, np.nan)


@dataclass(frozen=True)
class _OUAnswer:
    ou: object
    beta: np.ndarray
    cov_beta: np.ndarray
    x: np.ndarray
    sigma2: float


def _fit_ou(H, k, G, Lt, blocks, rss, taken, fit, problem):
    """The OU part by restricted maximum likelihood (:func:`.ou_torque.fit_ou`) on the Gram
    matrix of ``[J_theta, G Lt, G, r]`` (the named parameters and the trend fixed, the knots
    the OU's), columns scaled to unit norm; the white part's variance is that of the
    residual with every knot free (never below 1, as the F test's).

    Returns ``(answer, None)``, or ``(None, why)`` when it cannot be fitted (``why`` in
    words, for the JSON and the verdict: the constant and drift's answer then stands)."""
    m, n_t = G.shape[1], Lt.shape[1]
    E = np.zeros((k + m + 1, k + n_t + m + 1))
    E[:k, :k] = np.eye(k)
    E[k : k + m, k : k + n_t] = Lt
    E[k : k + m, k + n_t : k + n_t + m] = np.eye(m)
    E[-1, -1] = 1.0
    Hf = E.T @ H @ E
    kf = k + n_t
    fixed = Hf[:kf, :kf]
    sc = np.sqrt(np.diag(fixed))
    d = np.sqrt(np.maximum(np.diag(Hf)[kf:-1], 0.0))
    if np.any(sc == 0):
        return None, "a named effect or the trend has no column left beside the window states"
    if not np.any(d > 0):
        return None, "the knots' torque leaves no trace in the residual"
    # the white part's variance: the residual with the trend and every knot free
    Zall = Hf[:-1, :-1]
    S = np.r_[1.0 / sc, 1.0 / np.where(d > 0, d, 1.0)]
    bz = Hf[:-1, -1] * S
    sol = _solve_psd(Zall * S[:, None] * S[None, :], bz)
    dof_all = fit.n_res - fit.n_free - m  # the trend lies in the knots' span
    if dof_all <= 0:
        return None, "fewer residuals than the named effects, window states and knots"
    sigma2 = max((rss - float(bz @ sol)) / dof_all, 1.0)
    # the fixed effects' columns of unit norm, the knots in N m
    u = np.r_[S[:kf], np.ones(m + 1)]
    Hs = Hf * u[:, None] * u[None, :]
    span = max(float(tb[-1] - tb[0]) for tb in blocks)
    h = min(float(np.min(np.diff(tb))) for tb in blocks if tb.size > 1)
    dpos = d[d > 0]
    q0 = np.sqrt(sigma2) / float(np.median(dpos))  # a knot torque the noise just shows
    try:
        res = fit_ou(
            Hs, kf, blocks, sigma2,
            T_bounds=(h, OU_T_MAX_SPANS * span), q_bounds=(q0 * 1e-4, q0 * 1e4),
        )  # fmt: skip
    except np.linalg.LinAlgError:
        # the named effects and the trend nearly confounded with one another (frictions on
        # a narrow speed range): their posterior with the knots is not positive definite in
        # floating point, and the constant and drift's answer (the F test's) stands
        return None, NOT_POSITIVE_DEFINITE
    beta = res.beta * S[:kf]
    cov = res.cov_beta * S[:kf, None] * S[None, :kf]
    return _OUAnswer(ou=res, beta=beta, cov_beta=cov, x=res.x, sigma2=sigma2), None


def _means(blocks, Lt, trend, x):
    """Mean torque (N m) per block over its knots' span (trapezoid): the trend's constant
    plus the OU part's mean."""
    out = []
    i = 0
    for tb in blocks:
        tau = Lt[i : i + tb.size] @ trend
        if x is not None:
            tau = tau + x[i : i + tb.size]
        out.append(float(np.trapezoid(tau, tb) / max(tb[-1] - tb[0], 1e-12)) if tb.size > 1
                   else float(tau[0]))  # fmt: skip
        i += tb.size
    return np.asarray(out)


def _solve_psd(A, b):
    """``A^+ b`` for a symmetric positive semi-definite ``A`` (eigenvalues below ``1e-12``
    of the largest dropped: a direction without information)."""
    w, V = np.linalg.eigh(A)
    keep = w > 1e-12 * max(float(np.max(np.abs(w))), 1e-300)
    return V[:, keep] @ ((V[:, keep].T @ b) / w[keep])


def _inverse_diagonal(info: np.ndarray) -> np.ndarray:
    """The diagonal of ``inv(info)``, a direction without information at the rounding
    level (``1e-12`` of the largest eigenvalue: a named effect the nuisance makes exactly,
    its factor then about 1e6)."""
    w, V = np.linalg.eigh(info)
    w = np.maximum(w, 1e-12 * max(float(np.max(np.abs(w))), 1e-300))
    return (V**2) @ (1.0 / w)


def _projected_gram(J, k: int, G, r: np.ndarray, refine: int = 2) -> np.ndarray:
    """The Gram matrix of ``[J_theta, G, r]`` with the window-state columns ``An = J[:, k:]``
    projected off, ``(k + m + 1)^2`` dense: ``A'A - A'An X`` with ``X = (An'An)^+ An'A``,
    sparse products and solves only (linear in the samples; the projected columns
    themselves, dense, would cost the samples times the columns squared: a minute on an
    hour of 50 Hz samples).

    The window states take all but 1e-3 to 1e-4 of a knot's column, so the difference
    cancels six to eight digits: ``X`` from the normal equations (the states' Gram matrix
    has a condition number near 1e9) left 30 % errors in it. ``refine`` steps of iterative
    refinement of ``X`` bring it to 1e-7 of the explicitly projected columns' Gram matrix
    (``tests/discrepancy/test_discrepancy_slow_torque.py``)."""
    A = sp.hstack([J[:, :k], sp.csc_matrix(G), sp.csc_matrix(r[:, None])], format="csc")
    H = (A.T @ A).toarray()
    An = trailing_columns(J, k)  # J[:, k:] without its copy
    if An.shape[1] == 0:
        return H
    Gm = gram(An)  # scipy's sums, without its CSR copy of An
    c = np.sqrt(np.maximum(Gm.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    Gs = sp.csc_matrix(Dc @ Gm @ Dc)
    B = np.asarray((An.T @ A).toarray())
    Bs = B / c[:, None]
    Xs = solve_gram(Gs, Bs)
    for _ in range(refine):
        Xs = Xs + solve_gram(Gs, Bs - Gs @ Xs)
    H = H - B.T @ (Xs / c[:, None])
    return 0.5 * (H + H.T)
