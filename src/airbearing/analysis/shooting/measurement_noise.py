"""Coloured measurement noise: an AR(1) model of each output group, estimated with the fit.

The model is the one AR model of the engine (:class:`.autoregressive.AR`, order 1 here).

A motion-capture or gyro channel is often not white: its errors are correlated over
several samples (marker jitter filtered by the capture software, a gyro's internal
low-pass). Treated as white, such noise makes every standard error too small: an AR(1)
of coefficient 0.95 is credited with about 39 times the information it carries about a
slowly acting parameter. The grey-box answer (Kristensen, Madsen & Joergensen 2004) is a noise
model in the likelihood: each output group ``g`` gets the AR(1)

    e_t = phi_g e_(t-1) + s_g eps_t,    eps_t ~ N(0, 1)

in noise units, whose whitening (generalised least squares, the prediction errors) is a
lower bidiagonal matrix ``P`` applied to the measurement residual of every segment in
time order (a row that comes ``d`` samples after the previous usable one takes the
coefficient ``phi^d``; the first row of a series its marginal variance). The stacked
residual becomes ``[P r; W c]`` and everything downstream (the process-noise likelihood,
the Fisher errors, the bound, the sandwich) sees the innovations.

``(phi_g, s_g)`` are estimated by maximising the same Laplace marginal likelihood as the
process noise (:mod:`.process_noise`, the initial states integrated out: REML, which
corrects the bias of a coefficient estimated from residuals of fitted pieces), on the
Gauss-Newton linearisation of a fit on nearly free pieces: one sparse solve per trial
value, no new IPOPT run. The model is adopted only when

- the likelihood-ratio test against white noise (``phi = 0``, ``s`` free) is significant
  (chi-square with one degree of freedom, p < :data:`SIGNIFICANCE`): white noise stays
  white, and an in-model fit keeps its Cramer-Rao errors exactly;
- and its correlation time ``-dt / ln(phi)`` is below half a piece (the search's bound;
  an estimate at the bound with the likelihood still rising towards it is not adopted):
  a residual correlated over longer than that
  cannot be told from a trajectory error within the piece, and is left to the process
  noise (a torque the model misses, not the sensor);
- and its innovations have one variance in every piece (Levene's test): a sensor's noise is
  stationary, a misfit taken for noise stands out where it acts;
- and its marginal level is at least :data:`MIN_LEVEL` of the floor the weights assume:
  coloured noise is never smaller than what the data's differences see (they
  underestimate it), so a weaker one is no noise of the log but the integration's own
  error on a noise-free one (whose floor is the replay's resolution).

What the noise model cannot do is prove that a correlated residual is the sensor's: the
adequacy verdict therefore still says structure remains when the gap is above twice the
floor the data's differences see, and says in words that it may be coloured noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.autoregressive import AR
from airbearing.analysis.shooting.errors import _series
from airbearing.analysis.shooting.fit import solve_gram
from airbearing.analysis.shooting.penalty import piece_durations, start_yaw_profiled
from airbearing.analysis.shooting.sparse import cross_gram, gram

__all__ = [
    "MeasurementNoise",
    "SIGNIFICANCE",
    "estimate_measurement_noise",
    "set_measurement_noise",
    "whitening",
]

#: Likelihood-ratio p-value below which the AR(1) noise model replaces white noise.
SIGNIFICANCE = 1e-3
#: The noise's correlation time is searched up to this fraction of a piece; an estimate at
#: that bound, the likelihood still rising to it, is a trajectory error (a misfit the
#: process noise must take), not noise.
MAX_CORRELATION_OF_PIECE = 0.5
#: Log-likelihood gain from half the bound's correlation time to the bound above which the
#: likelihood "still rises" (a likelihood ratio of e^2: about chi2(1) at p = 0.05).
RISING = 2.0
#: Smallest marginal level (noise-floor units) of an adopted noise model.
MIN_LEVEL = 0.5
#: Most distinct sample intervals of one output group whose rows the noise estimate groups
#: (:class:`_Linearised`); a log with more is whitened row by row.
MAX_INTERVALS = 8
#: Search range of ``ln s`` (the innovation's level in noise-floor units: 0.007-150).
LOG_S = (-5.0, 5.0)


@dataclass(frozen=True)
class MeasurementNoise:
    """The AR(1) noise of each output group (module doc).

    Attributes
    ----------
    ar : dict
        ``group -> (phi, s)``: the coefficient per nominal sample interval and the
        innovation's standard deviation in noise-floor units.
    dt : float
        s, the nominal sample interval ``phi`` refers to.
    lr, p : dict
        ``group -> `` likelihood-ratio statistic and p-value against white noise.
    at_bound : tuple of str
        Groups whose correlation time sits at the search's bound (half a piece) with a
        flat likelihood there: adopted, but the weakest explanation of a correlated
        residual (a candidate effect may take it, see the discrepancy search).
    """

    ar: dict
    dt: float
    lr: dict
    p: dict
    at_bound: tuple = ()

    def correlation_time_s(self, group: str) -> float:
        """s, ``-dt / ln(phi)`` of ``group`` (0 when white)."""
        phi = self.ar.get(group, (0.0, 1.0))[0]
        return float(-self.dt / math.log(phi)) if 0.0 < phi < 1.0 else 0.0

    def level(self, group: str) -> float:
        """The marginal standard deviation of ``group``'s noise in noise-floor units,
        ``s / sqrt(1 - phi^2)`` (1 when white)."""
        if group not in self.ar:
            return 1.0
        phi, s = self.ar[group]
        return float(s / math.sqrt(1.0 - phi**2))

    def to_json(self) -> dict:
        """The JSON form: per group ``phi``, ``s``, ``correlation_time_s``, ``lr``, ``p``."""
        return {
            g: {
                "phi": float(phi),
                "s": float(s),
                "correlation_time_s": self.correlation_time_s(g),
                "lr": float(self.lr.get(g, math.nan)),
                "p": float(self.p.get(g, math.nan)),
            }
            for g, (phi, s) in self.ar.items()
        }


# ----------------------------------------------------------------------------
# the whitening


def whitening(problem, ar: dict, dt: float):
    """``(P, logdet)``: the whitening of the measurement residual (module doc).

    Parameters
    ----------
    problem : ShootingProblem
    ar : dict
        ``group -> (phi, s)``; a group not named stays white (identity rows).
    dt : float
        s, the sample interval ``phi`` refers to.

    Returns
    -------
    P : scipy.sparse.csc_matrix (n_meas, n_meas)
        Lower triangular in the residual's order.
    logdet : float
        ``log det P``.
    """
    n = problem.n_meas
    diag = np.ones(n)
    vals_o = []
    series = _series(problem)
    for group, (phi, s) in ar.items():
        model = AR(phi=np.array([float(phi)]), s=float(s))
        for rows, t in series.get(group, []):
            if rows.size == 0:
                continue
            d, sub = model.whitening_rows(t, dt)
            diag[rows] = d
            vals_o.append(sub)
    order, indices, indptr = _whitening_pattern(problem, tuple(ar))
    P = sp.csc_matrix(
        (np.concatenate([diag, *vals_o])[order], indices.copy(), indptr.copy()), shape=(n, n)
    )
    return P, float(np.sum(np.log(diag)))


def _whitening_pattern(problem, groups: tuple):
    """``(order, indices, indptr)``: the CSC structure of :func:`whitening`'s ``P`` when
    ``groups`` are coloured (the diagonal, then each series' subdiagonal in the order
    :func:`whitening` makes their values; ``order`` sorts those values into it). Kept on the
    problem: the noise estimate's likelihoods change the values only."""
    cache = problem.__dict__.setdefault("_whitening_patterns", {})
    if groups not in cache:
        n = problem.n_meas
        series = _series(problem)
        rows_o = [rows[1:] for g in groups for rows, _ in series.get(g, []) if rows.size]
        cols_o = [rows[:-1] for g in groups for rows, _ in series.get(g, []) if rows.size]
        r = np.concatenate([np.arange(n), *rows_o]).astype(np.int64)
        c = np.concatenate([np.arange(n), *cols_o]).astype(np.int64)
        order = np.lexsort((r, c))
        indptr = np.r_[0, np.cumsum(np.bincount(c, minlength=n))]
        # 32-bit while they fit (as P's own indices): the cache lives with the problem
        it = np.int32 if r.size < np.iinfo(np.int32).max else np.int64
        cache[groups] = (order.astype(it), r[order].astype(it), indptr.astype(it))
    return cache[groups]


def set_measurement_noise(problem, noise: MeasurementNoise | None) -> None:
    """Whiten ``problem``'s measurement residual with ``noise`` (None: white noise)."""
    if noise is None or not noise.ar:
        problem.meas_whitening, problem.meas_logdet, problem.measurement_noise = None, 0.0, None
        return
    P, logdet = whitening(problem, noise.ar, noise.dt)
    problem.meas_whitening, problem.meas_logdet = P, logdet
    problem.measurement_noise = noise


# ----------------------------------------------------------------------------
# the estimate


class _Linearised:
    """The Laplace log-likelihood of a fit's Gauss-Newton linearisation under any ``P``.

    ``P`` whitens each row with itself and the row before it in its series, with weights
    that depend on ``(phi, s)`` and on how many sample intervals lie between the two
    (:meth:`.AR.whitening_rows`). Rows are grouped by that interval (a regular log has
    one); each group's parts of ``J^T P^T P J``, ``J^T P^T P r`` and ``|P r|^2`` are fixed
    sums, so a trial ``(phi, s)`` weighs a few sparse matrices the size of the window
    states instead of whitening every row (:meth:`loglik`; a log of more than
    :data:`MAX_INTERVALS` distinct intervals takes the rows, :meth:`exact`).
    """

    def __init__(self, problem, fit, k: int) -> None:
        J = sp.csc_matrix(fit.extra["J"])
        r = np.asarray(fit.extra["r"], dtype=float)
        n = problem.n_meas
        P0 = problem.meas_whitening
        if P0 is not None:  # back to the raw residual
            lu = splu(sp.csc_matrix(P0))
            self.rm = lu.solve(r[:n])
            self.J = sp.csc_matrix(lu.solve(J[:n].toarray()))
        else:
            # the measurement rows are the first n of the fit's Jacobian, used in place (a
            # copy of them held 100s of MB on an hour of samples)
            self.rm, self.J = r[:n], J
        self.rp, self.Jp = r[n:], sp.csc_matrix(J[n:])
        # the defect rows do not depend on the measurement noise: their part of the Gram
        # matrix and of the gradient once
        self.Gp, self.gp = sp.csc_matrix(self.Jp.T @ self.Jp), self.Jp.T @ self.rp
        self.k = k
        self.problem = problem
        self._parts: dict = {}

    # -- the rows grouped by interval
    def _moments(self, rows, prev=None) -> tuple:
        """``(S0, S1, S2, g0, g1, g2, q0, q1, q2)``: the sums a whitened row ``d x_t + e
        x_(t-1)`` makes of its Gram matrix (``d^2 S0 + d e S1 + e^2 S2``), its gradient and
        its sum of squares, over ``rows`` (``prev``: the rows before them).

        The rows are taken from the fit's CSC Jacobian (no CSR copy of it) and the products
        made block of columns by block: scipy's sums of the same rows' ``A.T @ A``, ``A.T @
        B`` in their order (:func:`.sparse.cross_gram`)."""
        A, a = self._rows(rows), self.rm[rows]
        if prev is None:
            return (gram(A), None, None, A.T @ a, None, None, float(a @ a), 0.0, 0.0)
        B, b = self._rows(prev), self.rm[prev]
        BA = cross_gram(B, A)  # (A^T B)^T
        return (gram(A), BA.T + BA, gram(B), A.T @ a, A.T @ b + B.T @ a, B.T @ b,
                float(a @ a), 2.0 * float(a @ b), float(b @ b))  # fmt: skip

    def _rows(self, rows) -> sp.csc_matrix:
        """The measurement rows ``rows`` (in that order) as CSC, row indices sorted."""
        A = sp.csc_matrix(self.J[rows])
        A.sort_indices()
        return A

    def _split(self, dt: float):
        """The rows grouped by interval: ``(groups, M, Mg, mq, diag)``, or None when a
        group has more than :data:`MAX_INTERVALS` intervals.

        Every part of the Gram matrix is a column of ``M`` (its values on one common
        sparsity pattern), of the gradient a column of ``Mg``, of the sum of squares an
        entry of ``mq``: first the defect rows and the rows in no series (weight 1), then
        per output group (``groups``: ``(white, first, n_first, classes)``) the column of its
        rows unwhitened, of its series' first rows, and per interval ``(steps, n, column)``
        the columns ``S0, S1, S2`` of :meth:`_moments` from ``column`` on. ``diag``: where
        each diagonal entry lies in the pattern (-1: none)."""
        if dt in self._parts:
            return self._parts[dt]
        series = _series(self.problem)
        covered = np.zeros(self.rm.size, dtype=bool)
        terms: list = [None]  # (G, g, q) per column; the first filled last

        def add(G, g, q) -> int:
            terms.append((G, g, q))
            return len(terms) - 1

        groups = {}
        for name in self.problem.outputs:
            parts = [(rows, t) for rows, t in series.get(name, []) if rows.size]
            if not parts:
                continue
            first = np.concatenate([rows[:1] for rows, _ in parts])
            cur = np.concatenate([rows[1:] for rows, _ in parts])
            prev = np.concatenate([rows[:-1] for rows, _ in parts])
            steps = np.concatenate([np.maximum(np.diff(t) / dt, 1.0) for _, t in parts])
            # intervals equal to round-off (times summed from a log's steps) are one
            key = np.round(steps, 9)
            uniq = np.unique(key)
            if uniq.size > MAX_INTERVALS:
                self._parts[dt] = None
                return None
            covered[first] = covered[cur] = True
            m = self._moments(np.concatenate([first, cur]))
            white = add(m[0], m[3], m[6])
            m = self._moments(first)
            head = add(m[0], m[3], m[6])
            classes = []
            for u in uniq:
                at = key == u
                S0, S1, S2, g0, g1, g2, q0, q1, q2 = self._moments(cur[at], prev[at])
                col = add(S0, g0, q0)
                add(S1, g1, q1)
                add(S2, g2, q2)
                classes.append((float(np.mean(steps[at])), int(at.sum()), col))
            groups[name] = (white, head, first.size, classes)
        m = self._moments(np.flatnonzero(~covered))
        terms[0] = (m[0] + self.Gp, m[3] + self.gp, m[6] + float(self.rp @ self.rp))
        # the common pattern, and each part's values on it
        mats = [sp.csc_matrix(G) for G, _, _ in terms]
        U = sp.csc_matrix(sum(abs(G) for G in mats))
        U.sum_duplicates()
        U.sort_indices()
        nr = U.shape[0]
        ucol = np.repeat(np.arange(U.shape[1]), np.diff(U.indptr))
        where = ucol * nr + U.indices  # increasing: column-major
        M = np.zeros((where.size, len(mats)))
        for i, G in enumerate(mats):
            G = G.tocoo()
            np.add.at(M[:, i], np.searchsorted(where, G.col * nr + G.row), G.data)
        Mg = np.column_stack([np.asarray(g, dtype=float).ravel() for _, g, _ in terms])
        mq = np.array([float(q) for _, _, q in terms])
        diag = np.full(nr, -1)
        on = ucol == U.indices
        diag[U.indices[on]] = np.flatnonzero(on)
        self._pattern = (U.indices.copy(), U.indptr.copy(), U.shape, ucol)
        out = (groups, M, Mg, mq, diag)
        self._parts[dt] = out
        return out

    @staticmethod
    def _weights(groups: dict, n_terms: int, ar: dict):
        """``(w, log det P)``: the weight of each column of :meth:`_split` under ``ar``
        (the whitening of :meth:`.AR.whitening_rows`)."""
        w = np.zeros(n_terms)
        w[0] = 1.0
        logdet = 0.0
        for name, (white, head, n0, classes) in groups.items():
            if name not in ar:
                w[white] = 1.0
                continue
            phi, s = float(ar[name][0]), float(ar[name][1])
            d0 = math.sqrt(1.0 - phi**2) / s
            w[head] = d0**2
            logdet += n0 * math.log(d0)
            for steps, n, col in classes:
                a = math.copysign(abs(phi) ** steps, phi) if phi != 0.0 else 0.0
                ratio = (1.0 - a**2) / (1.0 - phi**2) if phi != 0.0 else 1.0
                d = 1.0 / (s * math.sqrt(ratio))
                e = -a * d
                w[col : col + 3] = (d * d, d * e, e * e)
                logdet += n * math.log(d)
        return w, logdet

    def loglik(self, ar: dict, dt: float) -> float:
        """The Laplace log-likelihood with the measurement rows whitened by ``ar``."""
        split = self._split(dt)
        if split is None:
            return self.exact(ar, dt)
        groups, M, Mg, mq, diag = split
        w, logdet = self._weights(groups, M.shape[1], ar)
        data = M @ w
        grad = Mg @ w
        d = np.where(diag >= 0, data[np.maximum(diag, 0)], 0.0)
        c = np.sqrt(np.maximum(d, 1e-300))
        rows, indptr, shape, cols = self._pattern
        Gs = sp.csc_matrix((data / (c[rows] * c[cols]), rows, indptr), shape=shape)
        step = solve_gram(Gs, grad / c) / c
        rss = float(mq @ w) - float(step @ grad)  # at the step
        return float(-0.5 * rss + logdet - 0.5 * self._logdet(Gs, c))

    def _logdet(self, Gs, c) -> float:
        """``log det`` of the window states' information (``Gs`` column-scaled by ``c``)."""
        Gd = start_yaw_profiled(self.problem, Gs[self.k :, self.k :])
        try:
            u = splu(sp.csc_matrix(Gd)).U.diagonal()
            ld = float(np.sum(np.log(np.abs(u)))) if np.all(u != 0) else np.inf
        except RuntimeError:
            ld = np.inf
        cd = c[self.k :]
        if Gd.shape[0] < cd.size:  # the start yaws profiled out: their scales with them
            cd = np.delete(cd, np.arange(self.problem.windows.n) * self.problem.n_delta)
        return ld + 2.0 * float(np.log(cd).sum())

    def _whitened(self, ar: dict, dt: float):
        """``(P J_m, P r_m, log det P)`` of the whitening by ``ar`` (P let go of after)."""
        P, logdet = whitening(self.problem, ar, dt)
        b = P @ self.rm
        # P on the measurement rows of J in place (P's columns padded with none to J's
        # rows): the whitened rows, the same products as P @ J[:n]
        N = self.J.shape[0]
        P = sp.csc_matrix((P.data, P.indices, np.r_[P.indptr, np.full(N - P.shape[1], P.nnz)]),
                          shape=(P.shape[0], N))  # fmt: skip
        return sp.csc_matrix(P @ self.J), b, logdet

    def exact(self, ar: dict, dt: float) -> float:
        """:meth:`loglik` row by row; keeps the whitened measurement rows after the step
        (``innovations``)."""
        A, b, logdet = self._whitened(ar, dt)
        G = sp.csc_matrix(gram(A) + self.Gp)
        c = np.sqrt(np.maximum(G.diagonal(), 1e-300))
        Dc = sp.diags(1.0 / c)
        Gs = sp.csc_matrix(Dc @ G @ Dc)
        step = solve_gram(Gs, (A.T @ b + self.gp) / c) / c
        self.innovations = e = b - A @ step  # the whitened measurement rows after the step
        ep = self.rp - self.Jp @ step
        return float(-0.5 * (e @ e + ep @ ep) + logdet - 0.5 * self._logdet(Gs, c))


def _max_phi(problem, dt: float) -> float:
    piece = float(np.mean(piece_durations(problem)[:-1])) if problem.windows.n > 1 else 0.0
    if not piece > 0:
        piece = float(problem.windows.length * dt)
    return math.exp(-dt / (MAX_CORRELATION_OF_PIECE * piece))


def _still_rising(ll, phi: float, phi_max: float, dt: float, at_best: float) -> bool:
    """True when the estimate sits at the correlation bound and the likelihood still rises
    towards it: by more than :data:`RISING` over the coefficient of half that correlation
    time (the data want a longer correlation than a sensor's: a misfit)."""
    from scipy import optimize  # scipy.optimize: 0.45 s CPU to import, loaded only when this runs

    if phi_max - phi > 0.1 * (1.0 - phi_max):
        return False
    tau_half = -dt / math.log(phi_max) / 2.0
    phi_half = math.exp(-dt / tau_half)
    half = optimize.minimize_scalar(
        lambda ls: ll([ls], fixed=phi_half), bounds=LOG_S, method="bounded"
    )
    return float(half.fun) - at_best > RISING


def _homoscedastic(problem, innovations: np.ndarray, group: str) -> bool:
    """True when the whitened residual of ``group`` has one variance in every piece
    (Levene's test, ``scipy.stats.levene`` about the medians, p >= :data:`SIGNIFICANCE`).

    A sensor's coloured noise is stationary: whitened by its model, every piece's
    innovations have the same spread. A misfit the model took for noise is not (a missing
    friction acts where the rate is high, a mis-scaled inertia during the slew), and the
    pieces where it acts stand out.
    """
    from scipy import stats  # scipy.stats: 1.2 s CPU to import, loaded only when this runs

    g = problem.outputs.index(group)
    rows = np.flatnonzero((problem.group == g) & problem.usable)
    piece = rows // problem.n_win_res
    groups = [innovations[rows[piece == j]] for j in np.unique(piece)]
    groups = [x for x in groups if x.size >= 8]
    if len(groups) < 2:
        return True
    return bool(stats.levene(*groups, center="median").pvalue >= SIGNIFICANCE)


def estimate_measurement_noise(problem, fit, k: int) -> MeasurementNoise | None:
    """The AR(1) noise of each output group from ``fit`` (module doc), or None (white).

    Parameters
    ----------
    problem : ShootingProblem
        On linked pieces, at the intensity ``fit`` was made at (nearly free pieces).
    fit : Fit
        A fit of ``problem`` whose first ``k`` free variables are the parameters.
    k : int

    Returns
    -------
    MeasurementNoise or None
        None when no group's noise is significantly coloured.
    """
    # scipy.optimize, scipy.stats: 0.45+1.2 s CPU to import, loaded only when this runs
    from scipy import optimize, stats

    w = problem.windows
    ok = w.weight[:, 1:] > 0
    if not ok.any():
        return None
    dt = float(np.median(w.dt[ok]))
    lin = _Linearised(problem, fit, k)
    phi_max = _max_phi(problem, dt)
    ar, lrs, ps, bound = {}, {}, {}, []
    for group in problem.outputs:

        def ll(x, group=group, fixed=None):
            phi = fixed if fixed is not None else float(np.clip(x[0], -0.9, phi_max))
            s = math.exp(float(x[-1]))
            return -lin.loglik({**ar, group: (phi, s)}, dt)

        white = optimize.minimize_scalar(
            lambda ls, group=group: ll([ls], group, 0.0), bounds=LOG_S, method="bounded"
        )
        best = optimize.minimize(
            ll,
            np.array([0.5, float(white.x)]),
            method="Nelder-Mead",
            bounds=[(-0.9, phi_max), LOG_S],
            options={"xatol": 1e-4, "fatol": 1e-3, "maxiter": 400},
        )
        phi, s = float(best.x[0]), math.exp(float(best.x[1]))
        lr = max(0.0, 2.0 * (float(white.fun) - float(best.fun)))
        p = float(stats.chi2.sf(lr, 1))
        lrs[group], ps[group] = lr, p
        strong = s / math.sqrt(1.0 - phi**2) >= MIN_LEVEL
        if p < SIGNIFICANCE and strong and not _still_rising(ll, phi, phi_max, dt, float(best.fun)):
            lin.exact({**ar, group: (phi, s)}, dt)
            if _homoscedastic(problem, lin.innovations, group):
                ar[group] = (phi, s)
                if phi_max - phi <= 0.1 * (1.0 - phi_max):
                    bound.append(group)
    if not ar:
        return None
    return MeasurementNoise(ar=ar, dt=dt, lr=lrs, p=ps, at_bound=tuple(bound))
