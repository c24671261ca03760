"""An Ornstein-Uhlenbeck torque on knots: its prior, and its correlation time and level by
restricted maximum likelihood on a linearised fit.

The slow torque of :mod:`.slow_torque` on one steady axis and log segment is
``tau(t) = a + b t + x(t)``: a constant and a linear drift (free, as fixed effects) and an
Ornstein-Uhlenbeck process ``dx = -x / T dt + s dW`` of correlation time ``T`` (s) and
stationary level ``q = s sqrt(T / 2)`` (N m), represented by its values on knots in time
and linear between them. The knot values are Gaussian, ``Cov(x_i, x_j) = q^2
exp(-|t_i - t_j| / T)``, and their precision is tridiagonal (the exact discretisation:
``phi = exp(-dt / T)``, innovation variance ``q^2 (1 - phi^2)``; :func:`ou_precision`).

The linearised model of the weighted residual ``y`` (window states projected off) is
``y = X beta + Z x + e``, ``e ~ N(0, sigma^2 I)``, with ``X`` the named parameters' and the
constant and drift's columns and ``Z`` the knots'. Integrating ``x`` (Gaussian) and ``beta``
(flat) gives the restricted likelihood of ``(T, q)`` (:func:`restricted_loglik`), which
needs only the Gram matrix of ``[X, Z, y]``: equivalent to a Kalman smoother of the
linearised model with the OU torque as a state, at a cost of one dense Cholesky of the
knots plus parameters (a few hundred at most) per evaluation, whatever the samples. Its
gradient and Fisher information in ``(log T, log q)`` are exact (the standard REML
expressions, ``1/2 tr(M Q_i M Q_j)`` with ``M = Z^T P Z``, in the knots' space). At the
maximum, the named parameters' estimate and covariance are the posterior ones (generalised
least squares with the OU prior): the errors marginalised over the slow torque.

The correlation time and level are not known, only estimated, so the named parameters'
answer is the posterior mixed over them (:func:`integrated_posterior`): a Gauss-Hermite
rule in ``(log T, log q)`` about the maximum, scaled by the inverse Fisher information,
each node weighted by the restricted likelihood there over the Gaussian the rule assumes
(flat prior in ``log T`` and ``log q`` between the search bounds; the quadrature of the
"grid" strategy of Rue, Martino & Chopin 2009, J. R. Stat. Soc. B 71, 319, sec. 3.1), and
the mixture's mean and covariance by the laws of total expectation and variance: the
weighted mean of the conditional means, and the weighted mean of the conditional
covariances plus the covariance of the conditional means.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.polynomial.hermite_e import hermegauss
from scipy.optimize import minimize_scalar
from scipy.special import logsumexp

__all__ = [
    "OUFit",
    "fit_ou",
    "integrated_posterior",
    "ou_covariance",
    "ou_precision",
    "posterior",
    "restricted_loglik",
]


def ou_covariance(t: np.ndarray, T: float, q: float) -> np.ndarray:
    """Dense covariance ``q^2 exp(-|t_i - t_j| / T)`` of an OU process at times ``t`` (s)."""
    t = np.asarray(t, dtype=float)
    return q**2 * np.exp(-np.abs(t[:, None] - t[None, :]) / T)


def ou_precision(t: np.ndarray, T: float, q: float) -> sp.csc_matrix:
    """Tridiagonal precision of an OU process at sorted times ``t`` (s): the inverse of
    :func:`ou_covariance`, from its Markov factorisation (``x_0 ~ N(0, q^2)``, ``x_i =
    phi_i x_{i-1} + N(0, q^2 (1 - phi_i^2))``, ``phi_i = exp(-(t_i - t_{i-1}) / T)``)."""
    t = np.asarray(t, dtype=float)
    n = t.size
    phi = np.exp(-np.diff(t) / T)
    v = 1.0 - phi**2  # innovation variance over q^2
    diag = np.zeros(n)
    diag[0] = 1.0
    diag[1:] = 1.0 / v
    diag[:-1] += phi**2 / v
    off = -phi / v
    return sp.diags([off, diag, off], [-1, 0, 1], format="csc") / q**2


def _logdet_precision(t: np.ndarray, T: float, q: float) -> float:
    phi = np.exp(-np.diff(t) / T)
    return -t.size * np.log(q**2) - float(np.sum(np.log1p(-(phi**2))))


@dataclass(frozen=True)
class _Blocks:
    """Knot times per block (steady axis, segment), in knot order."""

    times: tuple

    @property
    def m(self) -> int:
        return sum(t.size for t in self.times)

    def _gaps(self) -> np.ndarray:
        """Each knot's interval to the previous one of its block (inf at a block's start)."""
        return np.concatenate([np.r_[np.inf, np.diff(t)] for t in self.times])

    def precision(self, T, q) -> sp.csr_matrix:
        d, off = self.tridiagonal(T, q)
        return sp.diags([off, d, off], [-1, 0, 1], format="csr")

    def tridiagonal(self, T, q):
        """The precision's diagonal and first off-diagonal (:func:`ou_precision` per block,
        zero between blocks), vectorised over all knots."""
        phi = np.exp(-self._gaps()[1:] / T)  # 0 across a block boundary
        v = 1.0 - phi**2
        d = np.ones(self.m)
        d[1:] = 1.0 / v
        d[:-1] += phi**2 / v
        return d / q**2, -phi / v / q**2

    def logdet_precision(self, T, q) -> float:
        return sum(_logdet_precision(t, T, q) for t in self.times)

    def covariance_and_derivatives(self, T, q):
        """``Q``, ``dQ/dlog T``, ``dQ/dlog q`` (block diagonal, dense)."""
        Qs, DT = [], []
        for t in self.times:
            d = np.abs(t[:, None] - t[None, :])
            Q = q**2 * np.exp(-d / T)
            Qs.append(Q)
            DT.append(Q * d / T)
        Q = sla.block_diag(*Qs)
        return Q, sla.block_diag(*DT), 2.0 * Q


def restricted_loglik(H: np.ndarray, k: int, blocks, sigma2: float, T: float, q: float,
                      *, grad: bool = False, fisher: bool = False):  # fmt: skip
    """Restricted log-likelihood of ``(T, q)`` (up to a constant) from the Gram matrix.

    Parameters
    ----------
    H : ndarray (k + m + 1, k + m + 1)
        Gram matrix of ``[X, Z, y]``: ``k`` fixed-effect columns, the ``m`` knots' columns
        (unit: the residual per N m), the residual.
    k : int
        Fixed-effect columns.
    blocks : _Blocks or sequence of ndarray
        Knot times (s) per block, in the order of ``Z``'s columns.
    sigma2 : float
        Variance of the residual's white part (in the residual's weighted units).
    T, q : float
        Correlation time (s), level (N m).
    grad : bool
        Also return the gradient in ``(log T, log q)``.
    fisher : bool
        With ``grad``, also the Fisher information in ``(log T, log q)`` (else None).

    Returns
    -------
    float, or (float, ndarray (2,), ndarray (2, 2) or None)
        ``-inf`` when the fixed effects are not identified at these values.
    """
    blocks = blocks if isinstance(blocks, _Blocks) else _Blocks(tuple(map(np.asarray, blocks)))
    n = H.shape[0] - 1
    d, off = blocks.tridiagonal(T, q)
    A = H[:n, :n].copy()
    i = np.arange(k, n)
    A[i, i] += sigma2 * d
    A[i[:-1], i[1:]] += sigma2 * off
    A[i[1:], i[:-1]] += sigma2 * off
    b = H[:n, n]
    try:
        c, low = sla.cho_factor(A, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return (-np.inf, np.zeros(2), np.zeros((2, 2))) if grad else -np.inf
    u = sla.cho_solve((c, low), b, check_finite=False)
    # log|Lam| - log|A / sigma2| + b' A^-1 b / sigma2 (y'y / sigma2 constant)
    ll = 0.5 * (
        blocks.logdet_precision(T, q)
        - 2.0 * float(np.sum(np.log(np.diag(c))))
        + n * np.log(sigma2)
        + float(b @ u) / sigma2
    )
    if not grad:
        return ll
    Lam = blocks.precision(T, q)
    Sig = sigma2 * _cho_inverse(c)[k:, k:]  # posterior covariance of the knot values
    M = Lam.toarray() - (Lam @ (Lam @ Sig).T).T  # Z' P Z (Lam sparse: O(m^2))
    w = Lam @ u[k:]  # Z' P y (u[k:]: the knots' posterior mean)
    _, dT, dq = blocks.covariance_and_derivatives(T, q)
    g = np.array([0.5 * (w @ D @ w - np.sum(M * D)) for D in (dT, dq)])
    if not fisher:
        return ll, g, None
    MD = [M @ D for D in (dT, dq)]
    F = np.array([[0.5 * np.sum(a * b.T) for b in MD] for a in MD])
    return ll, g, F


def _cho_inverse(c: np.ndarray) -> np.ndarray:
    """The inverse of ``A`` from its lower Cholesky factor (LAPACK ``potri``), symmetric."""
    Ai, info = sla.lapack.dpotri(c, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"potri: {info}")
    Ai = np.tril(Ai)
    return Ai + np.tril(Ai, -1).T


@dataclass(frozen=True)
class OUFit:
    """The OU slow torque at its restricted-likelihood maximum.

    Attributes
    ----------
    T : float
        Correlation time, s.
    q : float
        Stationary level (standard deviation), N m.
    log_T_std : float
        Standard error of ``log T`` from the Fisher information (``inf`` when the level is at
        its lower bound: no OU part, ``T`` unidentified).
    at_lower : bool
        The level at its lower bound: the constant and drift describe the slow torque.
    loglik, loglik0 : float
        Restricted log-likelihood at the maximum and with no OU part (``q -> 0``).
    beta : ndarray (k,)
        Posterior mean of the fixed effects.
    cov_beta : ndarray (k, k)
        Their posterior covariance (the marginal one: the OU integrated out, and its
        correlation time and level too when ``nodes`` > 1).
    x : ndarray (m,)
        Posterior mean of the knot values, N m.
    cov_beta_at_max : ndarray (k, k) or None
        The posterior covariance at the maximum alone (``T`` and ``q`` taken as known).
    nodes : int
        Quadrature nodes in ``(log T, log q)`` that carry weight (1: at the maximum alone,
        as when the level is at its lower bound or the Fisher information is not finite).
    """

    T: float
    q: float
    log_T_std: float
    at_lower: bool
    loglik: float
    loglik0: float
    beta: np.ndarray
    cov_beta: np.ndarray
    x: np.ndarray
    cov_beta_at_max: np.ndarray | None = None
    nodes: int = 1


#: Gauss-Hermite nodes per dimension of ``(log T, log q)`` (:func:`integrated_posterior`):
#: exact for a conditional answer polynomial of degree 13 in them.
GH_NODES = 7


def fit_ou(H: np.ndarray, k: int, times, sigma2: float, *, T_bounds, q_bounds) -> OUFit:
    """``(T, q)`` by restricted maximum likelihood (Brent's method on ``log T`` with
    ``log q`` profiled out, each from a coarse grid's best point; the standard error of
    ``log T`` from the exact Fisher information of :func:`restricted_loglik`), and the
    fixed effects' posterior there. ``T_bounds`` (s) and ``q_bounds`` (N m) bound the search:
    below the knot spacing an OU is the white process noise's, beyond several log lengths
    it is the constant and drift."""
    blocks = _Blocks(tuple(np.asarray(t, dtype=float) for t in times))
    lo = np.log([T_bounds[0], q_bounds[0]])
    hi = np.log([T_bounds[1], q_bounds[1]])

    def lik(zT, zq):
        v = restricted_loglik(H, k, blocks, sigma2, np.exp(zT), np.exp(zq))
        return v if np.isfinite(v) else -1e300

    def profile(zT):  # the level's best at this correlation time: (log q, likelihood)
        grid = np.linspace(lo[1], hi[1], 9)
        vals = [lik(zT, zq) for zq in grid]
        i = int(np.argmax(vals))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        r = minimize_scalar(lambda zq: -lik(zT, zq), bounds=(a, b), method="bounded",
                            options={"xatol": 1e-3})  # fmt: skip
        return (r.x, -r.fun) if -r.fun >= vals[i] else (grid[i], vals[i])

    # Brent in one dimension twice (a Cholesky factor per point; the gradient's inverse
    # costs ten times more, and multi-threaded BLAS on small matrices of a busy machine a
    # hundred): the level profiled out at each correlation time, the correlation time from a
    # grid's best point and its neighbours
    gT = np.linspace(lo[0], hi[0], 8)
    prof = [profile(zT) for zT in gT]
    i = int(np.argmax([p[1] for p in prof]))
    a, b = gT[max(i - 1, 0)], gT[min(i + 1, gT.size - 1)]
    r = minimize_scalar(lambda zT: -profile(zT)[1], bounds=(a, b), method="bounded",
                        options={"xatol": 1e-3})  # fmt: skip
    zT = r.x if -r.fun >= prof[i][1] else gT[i]
    z = np.array([zT, profile(zT)[0]])
    T, q = np.exp(z)
    ll, _, F = restricted_loglik(H, k, blocks, sigma2, T, q, grad=True, fisher=True)
    at_lower = bool(z[1] <= lo[1] + 1e-6)
    with np.errstate(invalid="ignore", divide="ignore"):
        Fi = np.linalg.pinv(F) if np.all(np.isfinite(F)) else np.full((2, 2), np.inf)
    log_T_std = float(np.sqrt(Fi[0, 0])) if not at_lower and Fi[0, 0] > 0 else np.inf
    ll0 = restricted_loglik(H, k, blocks, sigma2, T, q_bounds[0] * 1e-3)
    beta, cov, x = posterior(H, k, blocks, sigma2, T, q)
    cov_at_max, nodes = cov, 1
    if not at_lower and np.all(np.isfinite(Fi)):
        beta, cov, x, nodes = integrated_posterior(H, k, blocks, sigma2, z, Fi, (lo, hi), ll)
    return OUFit(
        T=float(T),
        q=float(q),
        log_T_std=log_T_std,
        at_lower=at_lower,
        loglik=float(ll),
        loglik0=float(ll0),
        beta=beta,
        cov_beta=cov,
        x=x,
        cov_beta_at_max=cov_at_max,
        nodes=int(nodes),
    )


def integrated_posterior(H, k, times, sigma2, z, cov_z, bounds, ll_max, *, n=GH_NODES):
    """The fixed effects' and knots' posterior mixed over ``z = (log T, log q)``.

    Parameters
    ----------
    H, k, times, sigma2
        As :func:`posterior`.
    z : ndarray (2,)
        The restricted likelihood's maximum in ``(log T, log q)`` (T in s, q in N m).
    cov_z : ndarray (2, 2)
        Its inverse Fisher information there: the scale of the rule.
    bounds : (ndarray (2,), ndarray (2,))
        Lower and upper bounds of ``z`` (the search's): the prior's support, flat inside.
    ll_max : float
        The restricted log-likelihood at ``z``.
    n : int
        Nodes per dimension.

    Returns
    -------
    (ndarray (k,), ndarray (k, k), ndarray (m,), int)
        Mean and covariance of the fixed effects, mean of the knots (N m), and the number
        of nodes that carry weight. Gauss-Hermite in ``z = z_max + L xi`` (``L L' =
        cov_z``, each coordinate's spread at most a quarter of its bounds' range), each
        node's weight times ``exp(ll(z) - ll_max + |xi|^2 / 2)``, the
        restricted likelihood over the Gaussian the rule integrates against (module doc);
        nodes outside ``bounds`` or where the fixed effects are not identified carry none.
    """
    blocks = times if isinstance(times, _Blocks) else _Blocks(tuple(map(np.asarray, times)))
    xi, w = hermegauss(n)
    logw = np.log(w / np.sqrt(2.0 * np.pi))
    ev, V = np.linalg.eigh(0.5 * (cov_z + cov_z.T))
    L = V * np.sqrt(np.maximum(ev, 0.0))
    lo, hi = bounds
    # a Fisher scale wider than the bounds (a correlation time the logs do not resolve:
    # log T's std in the hundreds) would leave every node but the maximum outside them; the
    # rule's Gaussian is only where the likelihood is sampled (the weights correct for it),
    # so each coordinate's spread is capped at a quarter of its bounds' range: the outer
    # nodes (3.75 std) then reach across the whole range from either bound
    sd = np.sqrt(np.sum(L**2, axis=1))
    cap = (np.asarray(hi) - np.asarray(lo)) / 4.0
    L = L * np.minimum(1.0, cap / np.where(sd > 0, sd, 1.0))[:, None]
    logs, answers = [], []
    for i in range(n):
        for j in range(n):
            e = np.array([xi[i], xi[j]])
            zn = np.asarray(z, dtype=float) + L @ e
            if np.any(zn < lo) or np.any(zn > hi):
                continue
            T, q = np.exp(zn)
            ll = restricted_loglik(H, k, blocks, sigma2, T, q)
            if not np.isfinite(ll):
                continue
            try:
                answers.append(posterior(H, k, blocks, sigma2, T, q))
            except np.linalg.LinAlgError:
                continue
            logs.append(logw[i] + logw[j] + (ll - ll_max) + 0.5 * float(e @ e))
    if not answers:  # pragma: no cover - the maximum itself is a node (n odd)
        beta, cov, x = posterior(H, k, blocks, sigma2, *np.exp(z))
        return beta, cov, x, 1
    wt = np.exp(np.asarray(logs) - logsumexp(logs))
    B = np.array([a[0] for a in answers])
    X = np.array([a[2] for a in answers])
    beta = wt @ B
    dB = B - beta
    cov = np.einsum("i,ijk->jk", wt, np.array([a[1] for a in answers]))
    cov = cov + (dB * wt[:, None]).T @ dB  # the law of total variance
    return beta, 0.5 * (cov + cov.T), wt @ X, int(np.sum(wt > 1e-12))


def posterior(H: np.ndarray, k: int, times, sigma2: float, T: float, q: float):
    """``(beta, cov_beta, x)``: the fixed effects' posterior mean and covariance (flat prior:
    generalised least squares with the OU knots integrated out) and the knots' posterior
    mean, for the regression of ``y`` on ``[X, Z]`` whose Gram matrix is ``H``
    (:func:`restricted_loglik`)."""
    blocks = times if isinstance(times, _Blocks) else _Blocks(tuple(map(np.asarray, times)))
    n = H.shape[0] - 1
    A = H[:n, :n].copy()
    A[k:, k:] += sigma2 * blocks.precision(T, q).toarray()
    cf = sla.cho_factor(A, lower=True, check_finite=False)
    sol = sla.cho_solve(cf, H[:n, n], check_finite=False)
    Ak = sla.cho_solve(cf, np.eye(n)[:, :k], check_finite=False)[:k]
    return sol[:k], sigma2 * 0.5 * (Ak + Ak.T), sol[k:]
