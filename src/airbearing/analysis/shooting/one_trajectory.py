"""The linearised problem of ONE trajectory per segment, which the honest errors and the
Cramer-Rao bound of :mod:`.errors` are taken on: the measurement and continuity Jacobians
at a fit (those the fit kept when it was made on this problem as it is now, else evaluated
again), the bordered (KKT) solve of its weighted normal equations, and each residual's
influence on the parameters (``theta - theta_true ~ -M r``)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import _sparsetools
from scipy.sparse.linalg import splu

from airbearing.analysis.shooting.fit import gram
from airbearing.analysis.shooting.functions import _problem_functions
from airbearing.analysis.shooting.sparse import gram_rows


def _linearised(problem, fit, k: int):
    """The linearised problem of ONE trajectory per segment at ``fit``: ``(J, C, n)``, or
    None.

    ``J[:n]`` is the measurement Jacobian in noise units (whitened when the measurement
    noise is coloured; ``J`` may be the fit's whole Jacobian, its rows from ``n`` on the
    defects', not copied), ``C`` the continuity Jacobian of every linked pair, both in
    ``[theta; initial states]``. None when the windows are not linked or the fit has no
    parameter map.
    """
    w = problem.windows
    S_fit = fit.extra.get("S")
    if k == 0 or not w.linked or S_fit is None:
        return None
    pairs = np.flatnonzero(np.asarray(w.link, dtype=bool))
    nd = problem.n_delta
    rows = (pairs[:, None] * nd + np.arange(nd)).ravel()
    if _made_here(problem, fit, k):
        # a penalised fit of this problem under its measurement whitening and noise levels:
        # its Jacobian's measurement rows and the defects' Jacobian it kept are the same
        # numbers (to round-off) as the window Jacobian evaluated again at its answer
        # the measurement rows are read from the whole matrix (no copy of them)
        J = sp.csc_matrix(fit.extra["J"])
        return J, _held_fixed(fit, k, fit.extra["linearised"][2][rows]), problem.n_meas
    Sp, K = problem._pad(np.asarray(S_fit, dtype=float))
    fn = _problem_functions(*problem._key(K), True)[1]
    delta = np.asarray(fit.delta).reshape(-1, order="F")
    v = np.concatenate([fit.theta[:k], np.zeros(K - k), delta])
    p_base = fit.p - np.asarray(S_fit) @ fit.theta[:k]
    _, J, _, Jc = fn(v, p_base, Sp, problem._data)  # r, J, c, Jc (NumPy, scipy CSC)
    keep = np.r_[np.arange(k), np.arange(K, v.size)]
    Jm = J[:, keep]
    del J  # (the padded matrix let go before any other copy is made)
    if problem.meas_whitening is not None:  # coloured measurement noise: its innovations
        Jm = sp.csc_matrix(problem.meas_whitening @ Jm)
    return Jm, _held_fixed(fit, k, Jc[rows][:, keep]), Jm.shape[0]


def _held_fixed(fit, k: int, C):
    """The continuity Jacobian ``C`` with a row fixing each entry the fit held
    (:meth:`ShootingProblem.pin`), as the continuity fixes the linked states."""
    held = np.asarray(fit.extra.get("held", ()), dtype=int)
    if not held.size:
        return C
    E = sp.csr_matrix(
        (np.ones(held.size), (np.arange(held.size), k + held)), shape=(held.size, C.shape[1])
    )
    return sp.vstack([C, E], format="csr")


def _made_here(problem, fit, k: int) -> bool:
    """Whether ``fit`` kept its linearisation (``Fit.extra["linearised"]``: the problem's
    serial, the point, the measurement whitening and noise levels it was evaluated at, the
    defects' Jacobian) on ``problem`` as it is now, at ``fit``'s point, with ``k``
    parameters."""
    kept, J = fit.extra.get("linearised"), fit.extra.get("J")
    if kept is None or J is None or k != len(fit.theta):
        return False
    serial, (theta, delta, p, P, sigma), C = kept
    same = (
        np.array_equal(theta, fit.theta)
        and np.array_equal(delta, fit.delta)
        and np.array_equal(p, fit.p)
    )
    return (
        serial == problem._serial
        and same
        and P is problem.meas_whitening
        and np.array_equal(sigma, problem._data[-len(problem._sigmas()) :])
        and C.shape[1] == J.shape[1]
    )


def _kkt(Jm, C, k: int, level: np.ndarray | None = None):
    """``(cov0, M)`` of the linearised problem of one trajectory per segment, or None.

    ``cov0`` (k, k) is the parameters' block of the inverse of the bordered (KKT) matrix
    ``[[J' V^-1 J, C'], [C, 0]]`` (measurement Jacobian ``J`` in noise units, continuity
    Jacobian ``C``, ``V`` the rows' variances ``level``, default 1): their covariance on
    continuous trajectories. ``M`` (k, n_meas) maps the measurement residual to the
    parameters' first-order change of that weighted fit (``theta - theta_true ~ -M r``), so
    ``M Sigma M'`` is their covariance for any residual covariance ``Sigma``.
    Column-scaled, sparse (a null-space basis would need a dense SVD). None when the data
    cannot fix some direction.
    """
    Jm = sp.csc_matrix(Jm)
    sol = _kkt_solve(Jm, C, Jm.shape[0], k, level)
    if sol is None:
        return None
    if level is not None:  # (M of the weighted rows: the rows' weights in its columns)
        Jm = _weighted_rows(Jm, Jm.shape[0], 1.0 / np.sqrt(level))
    return sol[0], _influence(Jm, Jm.shape[0], sol, k)


def _kkt_solve(J, C, n: int, k: int, level: np.ndarray | None = None):
    """:func:`_kkt`'s ``(cov0, X, c)`` for the measurement Jacobian ``J[:n]``, or None:
    the bordered matrix's solution ``X`` for the parameters' unit vectors and the column
    scales ``c`` (:func:`_influence` makes ``M`` of them).

    The same numbers as scipy's products on ``J[:n]`` (its Gram matrix, the weighted rows'
    copy), without a copy of ``J``'s rows nor scipy's CSR copy for the Gram matrix: on an
    hour of 50 Hz three-axis samples each was about the size of the fit's Jacobian.
    """
    J = sp.csc_matrix(J)
    if level is not None:
        Jw = _weighted_rows(J, n, 1.0 / np.sqrt(level))
        F = gram(Jw)
        del Jw
    else:
        F = gram(J) if n >= J.shape[0] else gram_rows(J, n)
    F = sp.csc_matrix(F)
    c = np.sqrt(np.maximum(F.diagonal(), 0.0))
    if not np.all(c[:k] > 0):
        return None
    c = np.where(c > 0, c, 1.0)
    Dc = sp.diags(1.0 / c)
    Kkt = sp.bmat([[Dc @ F @ Dc, (C @ Dc).T], [C @ Dc, None]], format="csc")
    rhs = np.zeros((Kkt.shape[0], k))
    rhs[np.arange(k), np.arange(k)] = 1.0
    try:
        X = splu(Kkt).solve(rhs)
    except RuntimeError:  # singular
        return None
    if not np.all(np.isfinite(X)):
        return None
    cov0 = X[:k] / np.outer(c[:k], c[:k])
    return 0.5 * (cov0 + cov0.T), X, c


def _weighted_rows(J: sp.csc_matrix, n: int, w: np.ndarray) -> sp.csc_matrix:
    """``diag(w) J[:n]`` as scipy's product makes it (CSC, its row indices sorted, entries
    whose product is exactly 0 left out), written a block of columns at a time into one
    copy of the entries (scipy's product made two, and its CSC copy of them a third)."""
    J = sp.csc_matrix(J)
    wf = np.zeros(J.shape[0])
    wf[:n] = w  # (rows from n on weighted 0: left out as the products 0 are)
    data = np.empty(J.nnz)
    rows = np.empty(J.nnz, dtype=J.indices.dtype)
    indptr = np.zeros(J.shape[1] + 1, dtype=J.indptr.dtype)
    nc = J.shape[1]
    edges = np.unique(np.r_[np.arange(0, nc, max(1, -(-nc // 16))), nc])
    m = 0
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        p0, p1 = J.indptr[a], J.indptr[b]
        idx = J.indices[p0:p1]
        d = J.data[p0:p1] * wf[idx]
        nz = d != 0
        kept = int(nz.sum())
        data[m : m + kept] = d[nz]
        rows[m : m + kept] = idx[nz]
        before = np.r_[0, np.cumsum(nz)]  # entries kept before each of the block's
        indptr[a + 1 : b + 1] = m + before[J.indptr[a + 1 : b + 1] - p0]
        m += kept
    out = sp.csc_matrix((data[:m], rows[:m], indptr), shape=(n, nc))
    out.sort_indices()
    return out


def _influence(J: sp.csc_matrix, n: int, sol, k: int) -> np.ndarray:
    """:func:`_kkt`'s ``M`` (k, n) from :func:`_kkt_solve`'s ``sol`` and the measurement
    Jacobian ``J[:n]``: scipy's ``((J Dc) X).T / c`` to the bit, ``J Dc`` made a block of
    columns at a time (each entry ``J_ij / c_j`` summed into the rows in column order, as
    scipy's product sums them) instead of whole."""
    _, X, c = sol
    J = sp.csc_matrix(J)
    n_r, n_v = J.shape
    d = 1.0 / c
    Xv = X[:n_v]
    Y = np.zeros((n_r, Xv.shape[1]))
    edges = np.unique(np.r_[np.arange(0, n_v, max(1, -(-n_v // 16))), n_v])
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        p0, p1 = J.indptr[a], J.indptr[b]
        data = J.data[p0:p1] * np.repeat(d[a:b], np.diff(J.indptr[a : b + 1]))
        _sparsetools.csc_matvecs(
            n_r, b - a, Xv.shape[1], J.indptr[a : b + 1] - p0, J.indices[p0:p1], data,
            np.ascontiguousarray(Xv[a:b]).ravel(), Y.ravel(),
        )  # fmt: skip
    return np.asarray(Y[:n].T / c[:k, None])
