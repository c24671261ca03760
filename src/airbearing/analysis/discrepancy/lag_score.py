"""The rate-sensor lag's score test on linked pieces: what the lag Model could explain at most.

On linked pieces (:mod:`airbearing.analysis.shooting.process_noise`) every window's initial
state is free but its continuity defects are penalised: the fitted residual is the stack
``[r_m; W c]`` of the (whitened) measurement rows and the whitened defects. The lag Model
adds to it

* the lag ``tau``: to first order the rate sensor reads ``w - tau w'``, so the measurement
  rows move by ``tau x`` with ``x`` the measured rate derivative in noise units
  (:func:`lag_regressor`), whitened as the rows are;
* a start of the lagged rate in every window (one per rate axis), whose effect on the
  readings decays as ``exp(-t / tau)`` (the lag's equation is linear in it); and
* the defects of the lagged rate between linked windows, penalised like the rate's.

The lag does not change the true motion, so the attitude and rate defects (and their
rows of the stacked Jacobian) are the lag-free problem's. In the Gauss-Newton linearisation
at the current fit, at a lag ``tau`` whose starts reach ``R(tau) = ceil(3 tau / dt)``
samples, the lag Model's smallest weighted RSS is at least

    g_R(tau) = min over z of |r + A z + tau x|^2 over every row but the "head" rows of R,

with ``A`` every column of the current fit's stacked Jacobian (the chosen effects and all
window states, refitted with the lag), because (1) the lagged rate's defects are
non-negative terms (dropped); (2) the lagged rate's starts act only on each window's first
``R`` rate samples (to ``exp(-3)`` of their size; with coloured measurement noise, on the
whitened rows those samples reach): leaving those rows out is the same as giving every one
of them a free value, which spans whatever the starts could do there. ``g_R`` is a
quadratic in ``tau`` (its minimum ``g_R(tau_R)``, its curvature ``|x_perp|^2``) and falls as
``R`` grows (more rows free). So over the lags of a band of reaches ``R1..R2``
(``tau`` in ``((R1 - 1) dt / 3, R2 dt / 3]``) the RSS is at least ``g_R2`` at the band's
point nearest ``tau_R2``; the bands double (1, 2, 3-4, 5-8, ...) up to the lag's physical
bound, and the bound is the smallest over them: every lag from 0 to its bound is covered.

The bound is conservative in what it credits (every head row free, no lag defect
penalised, the effects and window states refitted jointly with the lag); it holds for the
linearised problem. The screen that uses it keeps a factor ``1 / SCREEN_FRACTION`` (2) for
the nonlinearity (:func:`.screen.screened_lag`), as on unlinked windows. Measured against
the IPOPT fit of the lag Model: a 20 s platform oscillation without a lag, bound 6.6,
IPOPT 7.0 (its window states refitted nonlinearly); the 60 s and 10 min seed-004 logs,
bound 3.4e-4 and 5.4e-3, IPOPT 1.7e-4 and 4.3e-4, against the 186 and 2190 naming needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.discrepancy.candidates import smoothed
from airbearing.analysis.shooting.sparse import gram

__all__ = ["LagBound", "lag_regressor", "linked_lag_bound"]

#: Relative ridge on the scaled normal equations (a direction no data fixes is left at 0
#: instead of making the factorisation fail; 1e-12 of a unit diagonal changes no projection
#: that matters).
RIDGE = 1e-12


@dataclass(frozen=True, eq=False)
class LagBound:
    """The linearised lag Model's best fit with every head row free (module doc).

    Attributes
    ----------
    tau : float
        s, the lag there (>= 0).
    std : float
        s, its standard error (``s2 / |x_perp|^2``, ``s2`` the current fit's variance).
    rss : float
        The bound on the lag Model's weighted RSS (noise units squared).
    e : ndarray
        The linearised residual at ``tau`` on every row (head rows included), for its gap.
    reach : int
        Samples of each window's rate rows left out (the lagged rate's starts).
    """

    tau: float
    std: float
    rss: float
    e: np.ndarray
    reach: int


def lag_regressor(problem, datas) -> np.ndarray:
    """``x`` (``n_win_res n_windows``): the measured rate derivative in noise units on the rate
    rows of every window (rows the Savitzky-Golay derivative trusts, usable rows; 0
    elsewhere), in the measurement residual's layout (:class:`.ShootingProblem`)."""
    w, nw, n = problem.windows, problem.windows.n, problem.n_win_res
    L, na = w.length, problem.n_rate
    wdots = [smoothed(d)[1:] for d in datas]
    x = np.zeros(n * nw)
    for j in range(nw):
        w_dot, ok = wdots[int(w.source[j])]
        rows = w.rows[j]
        good = ok[rows] & (w.weight[j] > 0)
        vals = np.where(good[:, None], w_dot[rows], 0.0) / problem.sigma_rate
        x[j * n : j * n + L * na] = vals.reshape(-1)  # rate group first, sample-major
    return x


def _head_rows(problem, reach: int) -> np.ndarray:
    """Measurement rows (whitened) the first ``reach`` rate samples of every window reach."""
    nw, n, na = problem.windows.n, problem.n_win_res, problem.n_rate
    m = min(reach, problem.windows.length) * na
    head = np.zeros(problem.n_meas, dtype=bool)
    for j in range(nw):
        head[j * n : j * n + m] = True
    P = problem.meas_whitening
    if P is not None:  # a whitened row mixes its raw row with the ones before it
        head = np.asarray(abs(sp.csc_matrix(P)) @ head.astype(float)).ravel() > 0
    return head


class _Projection:
    """Least squares in the columns ``A`` on the rows ``keep`` (sparse normal equations).

    The rows left out are zeros of a copy of ``A``'s values (``A``'s index arrays shared),
    not a copy of the kept rows (values and indices: some 80 MB on an hour of 50 Hz
    three-axis samples). The same numbers: each sum over a column's entries runs in the
    same order, a zero row adding exact zeros, and scipy's products leave out the sums
    that are exactly zero, so the normal matrix has the kept rows' pattern.
    """

    def __init__(self, A: sp.csc_matrix, keep: np.ndarray) -> None:
        self.keep = keep
        data = np.where(keep[A.indices], A.data, 0.0)
        self.A = sp.csc_matrix((data, A.indices, A.indptr), shape=A.shape)
        G = sp.csc_matrix(gram(self.A))  # (scipy's sums, without its CSR copy of A)
        c = np.sqrt(np.maximum(G.diagonal(), 0.0))
        self.c = np.where(c > 0, c, 1.0)
        Dc = sp.diags(1.0 / self.c)
        self.lu = splu(sp.csc_matrix(Dc @ G @ Dc + RIDGE * sp.identity(G.shape[0])))

    def coef(self, v: np.ndarray) -> np.ndarray:
        """The least-squares coefficients of ``v`` (all rows; the left-out ones are not
        read) in ``A``."""
        return self.lu.solve((self.A.T @ np.where(self.keep, v, 0.0)) / self.c) / self.c

    def fitted(self, a: np.ndarray) -> np.ndarray:
        """``A a`` on the kept rows."""
        return (self.A @ a)[self.keep]


def _nonempty_columns(J: sp.csc_matrix, cols: np.ndarray) -> sp.csc_matrix:
    """``J[:, cols]`` for the columns ``cols`` (ascending) holding every entry of ``J``,
    sharing ``J``'s arrays: the columns left out are empty, so the others' entries are
    ``J``'s in their order (a copy of them was about the size of the fit's Jacobian)."""
    indptr = np.r_[J.indptr[cols], J.indptr[-1]].astype(J.indptr.dtype)
    return sp.csc_matrix((J.data, J.indices, indptr), shape=(J.shape[0], cols.size))


def linked_lag_bound(problem, current, datas, tau_max: float) -> LagBound | None:
    """The smallest RSS the linearised lag Model can reach on linked windows (module doc).

    Parameters
    ----------
    problem : ShootingProblem
        The lag-free problem on linked windows, at the intensity ``current`` was made at.
    current : Fit
        The current fit (its ``extra["r"]`` and ``extra["J"]``: the stacked residual and
        Jacobian).
    datas : sequence of ReplayData
        The logs (for the measured rate derivative).
    tau_max : float
        s, the lag's physical upper bound.

    Returns
    -------
    LagBound or None
        At the band of reaches that gives the smallest bound; None when the fit keeps no
        Jacobian or a normal matrix cannot be factorised.
    """
    if "J" not in current.extra or "r" not in current.extra:
        return None
    r = np.asarray(current.extra["r"], dtype=float)
    J = sp.csc_matrix(current.extra["J"])
    n = problem.n_meas
    x = lag_regressor(problem, datas)
    P = problem.meas_whitening
    xs = np.r_[x if P is None else P @ x, np.zeros(r.size - n)]  # no defect moves with tau
    nonempty = np.diff(J.indptr) > 0  # held states: zero columns, left out
    A = J if nonempty.all() else _nonempty_columns(J, np.flatnonzero(nonempty))
    dt = float(np.median(problem.windows.dt[problem.windows.dt > 0]))
    s2 = current.rss / max(current.n_res - current.n_free, 1)
    r_top = min(max(1, math.ceil(3 * tau_max / dt)), problem.windows.length)
    best = None
    r1 = 1
    while r1 <= r_top:
        r2 = min(max(1, 2 * (r1 - 1)), r_top)  # bands 1, 2, 3-4, 5-8, ...
        lo, hi = (r1 - 1) * dt / 3, min(r2 * dt / 3, tau_max)
        keep = np.r_[~_head_rows(problem, r2), np.ones(r.size - n, dtype=bool)]
        proj = None  # (the last band's let go before this one's is made)
        try:
            proj = _Projection(A, keep)
        except RuntimeError:  # singular even with the ridge: IPOPT's to handle
            return None
        a_r, a_x = proj.coef(r), proj.coef(xs)
        rp, xp = r[keep] - proj.fitted(a_r), xs[keep] - proj.fitted(a_x)
        xx = float(xp @ xp)
        tau = float(np.clip(-float(xp @ rp) / xx, lo, hi)) if xx > 0 else lo
        e_kept = rp + tau * xp
        rss = max(float(e_kept @ e_kept), 1e-300)
        if best is None or rss < best.rss:
            e = r + tau * xs - A @ (a_r + tau * a_x)
            std = math.sqrt(s2 / xx) if xx > 0 else math.inf
            best = LagBound(tau=tau, std=std, rss=rss, e=e, reach=r2)
        r1 = r2 + 1
    return best
