"""A fit of a shooting problem (:class:`Fit`), the solver-status policy and the
Gauss-Newton errors of the parameters with the window states eliminated."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.functions import FISHER_RCOND
from airbearing.analysis.shooting.sparse import gram as sparse_gram

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
    # "r", "J" (scipy CSC, unscaled) at the fit; with continuity also "N", the basis of the
    # directions that keep it (theta first, :func:`~.constrained.null_space_basis`). A fit
    # made from a shared Jacobian keeps "J_blocks" instead of "J" (:func:`fit_jacobian`)
    extra: dict = field(default_factory=dict)


def fit_jacobian(fit: Fit):
    """The Jacobian of ``fit``'s weighted residual in ``[theta; vec(delta)]`` (scipy sparse).

    ``fit.extra["J"]`` as it is, or, for a fit that keeps ``extra["J_blocks"] = (A, E, Jd)``
    (the discrepancy search's Gauss-Newton steps, :mod:`airbearing.analysis.discrepancy.screen`:
    every candidate of a round shares the round's parameter columns ``A`` and the window
    states' columns ``Jd``; ``E`` maps the fit's parameters to ``A``'s columns), the matrix
    ``[A E, Jd]`` made now: the same numbers, without a copy of ``Jd`` and of the parameter
    columns per candidate (on an hour of 50 Hz three-axis samples some 45 MB and 9 MB per
    parameter each). A 2-tuple ``(At, Jd)`` is taken as ``[At, Jd]``. A fit that keeps
    ``extra["J_made"] = (source, E)`` instead has ``source.columns_of(E)`` make
    ``(A E, Jd)`` again (the first round's step-judged fits, kept to the honest errors at
    the end: :class:`airbearing.analysis.discrepancy.linearisation.Columns`, which makes only
    the columns of ``A`` that ``E`` reads).

    Parameters
    ----------
    fit : Fit

    Returns
    -------
    scipy sparse matrix (n_res, n_free)
    """
    if "J" in fit.extra:
        return fit.extra["J"]
    if "J_made" in fit.extra:  # the shared columns made again (their maker, the fit's E)
        source, E = fit.extra["J_made"]
        At, Jd = source.columns_of(E)
        return sp.hstack([sp.csc_matrix(At), Jd]).tocsc()
    *At, Jd = fit.extra["J_blocks"]
    At = At[0] @ At[1] if len(At) == 2 else At[0]
    return sp.hstack([sp.csc_matrix(At), Jd]).tocsc()


def fit_jacobian_split(fit: Fit, k: int):
    """``(At, Jn)``: :func:`fit_jacobian`'s first ``k`` columns (dense) and the rest (CSC),
    made from the blocks a fit keeps (``extra["J_made"]`` or ``["J_blocks"]``) without
    the whole matrix: ``At`` as ``fit_jacobian(fit)[:, :k].toarray()``, ``Jn`` the window
    states' block itself (the same numbers to the bit). None for a fit that keeps its
    Jacobian whole, whose split is not ``k`` parameter columns and the rest, or whose
    blocks are not CSC (take :func:`fit_jacobian` then). On an hour of 50 Hz three-axis
    samples the whole matrix made again for the honest errors was some 120 MB.

    Parameters
    ----------
    fit : Fit
    k : int
        Number of leading (parameter) columns.

    Returns
    -------
    tuple (ndarray (n_res, k), scipy CSC (n_res, n_free - k)) or None
    """
    if "J" in fit.extra:
        return None
    mine = False  # the parameter columns made for this call (no one else holds them)
    if "J_made" in fit.extra:
        source, E = fit.extra["J_made"]
        if np.shape(E)[1] != k:
            return None
        At, Jd = source.columns_of(E)
        mine = True
    elif "J_blocks" in fit.extra:
        *At, Jd = fit.extra["J_blocks"]
        At = At[0] @ At[1] if len(At) == 2 else At[0]
    else:
        return None
    if At.shape[1] != k or not (sp.issparse(Jd) and Jd.format == "csc"):
        return None
    # as fit_jacobian's CSC makes it (an exact zero +0.0, not -0.0; column-major, as
    # scipy's dense copy of a CSC matrix): adding +0.0 does both to the bit, without the
    # sparse copy (about 90 MB for three columns on an hour of 50 Hz three-axis samples),
    # in place when the columns were made column-major for this call
    if mine and At.flags.f_contiguous:
        return np.add(At, 0.0, out=At), Jd
    return np.add(At, 0.0, order="F"), Jd


def solve_gram(G, B: np.ndarray) -> np.ndarray:
    """``G^+ B`` for a symmetric positive semi-definite Gram matrix ``G`` (sparse or dense).

    A sparse LU when ``G`` is sparse and non-singular (the window states couple only their
    neighbours: linear in their number), else the pseudo-inverse (a singular ``G``: states
    the data cannot fix).
    """
    B = np.asarray(B, dtype=float)
    if sp.issparse(G) and G.shape[0] > 32:
        from scipy.sparse.linalg import splu

        try:
            with np.errstate(all="ignore"):
                X = splu(sp.csc_matrix(G)).solve(B if B.ndim == 2 else B[:, None])
            X = X if B.ndim == 2 else X[:, 0]
            R = G @ X - B
            if np.all(np.isfinite(X)) and np.linalg.norm(R) <= 1e-8 * max(
                np.linalg.norm(B), 1e-300
            ):
                return X
        except RuntimeError:  # exactly singular
            pass
    Gd = G.toarray() if sp.issparse(G) else np.asarray(G)
    return np.linalg.pinv(Gd, rcond=1e-12, hermitian=True) @ B


def gram(Js):
    """``Js^T Js``; for a scipy sparse ``Js`` the CSC matrix :func:`.sparse.gram` makes block
    of columns by block (the same matrix to the bit as scipy's whole product, without its
    CSR copy of ``Js``: some 100 MB on an hour of 50 Hz three-axis samples)."""
    if not sp.issparse(Js):
        return Js.T @ Js
    return sparse_gram(Js)


def _reduced(Js, k: int):
    """Schur complement of the nuisance block of ``Js^T Js`` (columns ``k:`` eliminated),
    symmetrised, and the parameters' own block."""
    F = gram(Js)
    if sp.issparse(F):
        F = sp.csc_matrix(F)
        Ftt, Ftd, Fdd = F[:k, :k].toarray(), F[:k, k:].toarray(), F[k:, k:]
    else:
        F = np.asarray(F)
        Ftt, Ftd, Fdd = F[:k, :k], F[:k, k:], F[k:, k:]
    if Fdd.shape[0]:
        Fr = Ftt - Ftd @ solve_gram(Fdd, Ftd.T)
    else:
        Fr = Ftt
    return 0.5 * (Fr + Fr.T), Ftt


#: Relative eigenvalue below which a scaled information matrix is singular in that
#: direction (the one rule of the package's pseudo-inverses of information matrices).
PINV_RCOND = 1e-12


def information_inverse(F: np.ndarray, rcond: float = PINV_RCOND) -> tuple[np.ndarray, int]:
    """The pseudo-inverse of an information (Gram, Fisher) matrix and its rank.

    ``F`` is scaled by its diagonal (each parameter's own information; units and
    magnitudes differ by many decades), eigen-decomposed, and the directions with an
    eigenvalue below ``rcond`` times the largest are dropped (the same as
    ``numpy.linalg.pinv(..., rcond, hermitian=True)`` of the scaled matrix); the result is
    scaled back. A caller that must not report a number on a rank-deficient matrix tests
    ``rank < len(F)``.

    Parameters
    ----------
    F : numpy.ndarray (k, k)
        Symmetric positive semi-definite, in the parameters' units.
    rcond : float
        Relative eigenvalue cut-off.

    Returns
    -------
    inverse : numpy.ndarray (k, k)
        In the inverse units of ``F``; NaN everywhere when ``F`` is not finite.
    rank : int
        Directions kept (0 when ``F`` is not finite).
    """
    F = np.asarray(F, dtype=float)
    c = np.sqrt(np.maximum(np.diag(F), 0.0))
    c = np.where(c > 0, c, 1.0)
    Fs = F / np.outer(c, c)
    if not np.all(np.isfinite(Fs)):
        return np.full(F.shape, np.nan), 0
    ev, V = np.linalg.eigh(0.5 * (Fs + Fs.T))
    good = ev > rcond * max(float(np.max(np.abs(ev), initial=0.0)), 1e-300)
    inv = (V[:, good] / ev[good]) @ V[:, good].T
    return inv / np.outer(c, c), int(np.count_nonzero(good))


def theta_errors(J, k: int, s2: float, names=None, drop=None):
    """Standard errors of the first ``k`` columns of ``J`` with the others eliminated.

    Parameters
    ----------
    J : scipy sparse or ndarray (n_res, n_free)
        Jacobian of the weighted residual at the fit.
    k : int
        Number of parameters (the leading columns); the rest are nuisance (initial states).
    s2 : float
        Residual variance factor (reduced chi-square).
    drop : array of int, optional
        Nuisance columns (indices ``>= k``) left out, as if ``J`` had not held them (a
        pinned window state): taken out in the column scaling's product, without a copy
        of ``J`` less those columns.

    Returns
    -------
    std : ndarray (k,)
        1-sigma, NaN where not identifiable.
    cov : ndarray (k, k)
    reasons : tuple of str
        "" or why the parameter cannot be identified.
    """
    if k == 0:
        return np.zeros(0), np.zeros((0, 0)), ()
    # the Gram matrix from the sparse Jacobian (windows are independent blocks): a dense
    # product of the whole residual would cost more than the fit
    Jd = sp.csc_matrix(J) if sp.issparse(J) else np.asarray(J)
    col = (
        np.sqrt(np.asarray(Jd.power(2).sum(axis=0)).ravel())
        if sp.issparse(Jd)
        else np.linalg.norm(Jd, axis=0)
    )
    n = Jd.shape[1]
    keep = np.arange(n) if drop is None or not len(drop) else np.setdiff1d(np.arange(n), drop)
    col = col[keep]
    c = np.where(col > 0, col, 1.0)
    if sp.issparse(Jd):  # the kept columns, each divided by its norm, in one product
        pick = sp.csc_matrix((1.0 / c, (keep, np.arange(keep.size))), shape=(n, keep.size))
        Js = Jd @ (sp.diags(1.0 / c) if keep.size == n else pick)
    else:
        Js = (Jd if keep.size == n else Jd[:, keep]) / c
    Fr, Ftt = _reduced(Js, k)
    del Js
    return reduced_errors(Fr, Ftt, col[:k], s2)


def reduced_errors(Fr: np.ndarray, Ftt: np.ndarray, col: np.ndarray, s2: float):
    """:func:`theta_errors` from the reduced Fisher matrix of the column-scaled Jacobian.

    Parameters
    ----------
    Fr : ndarray (k, k)
        Schur complement of the nuisance block of ``Js^T Js`` (symmetric), ``Js`` the
        Jacobian with each column divided by its norm (a zero column left as it is).
    Ftt : ndarray (k, k)
        The parameters' own block of ``Js^T Js``.
    col : ndarray (k,)
        The parameters' column norms of the unscaled Jacobian (their units' inverse).
    s2 : float
        Residual variance factor (reduced chi-square).

    Returns
    -------
    std, cov, reasons
        As :func:`theta_errors`.
    """
    k = col.size
    reasons = ["" for _ in range(k)]
    for i in range(k):
        if not col[i] > 0:
            reasons[i] = "no usable sample is sensitive to it (nothing in the log excites it)"
    c = np.where(col > 0, col, 1.0)
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
    cov = cov_s / np.outer(c, c)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    for i in range(k):
        if not ok[i] or not std[i] > 0:
            std[i] = np.nan
            cov[i, :] = cov[:, i] = np.nan
            if not reasons[i]:
                reasons[i] = "zero variance: not identifiable from this log"
    return std, cov, tuple(reasons)
