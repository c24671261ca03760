"""A round's linearisation: the residual and its exact Jacobian at the current fit in
every parameter a candidate moves, from ONE evaluation of the window function, each
window's initial state eliminated in its own small normal equations.

:class:`Linearisation` holds the reduced normal equations and makes each candidate's
Gauss-Newton step within its physical bounds (:class:`Step`, the box-constrained minimum
of the quadratic model by its active sets), the likelihood ratio at a step, and a step's
:class:`.Fit` with its errors. :class:`Columns` makes the Jacobian's columns again once
they are let go (the honest errors at the end of a search). :func:`linearise` makes the
round's; :func:`one_value_linearisation` the one at a per-axis candidate's one-value fit.
What the screen decides from them is :mod:`.screen`'s.
"""

from __future__ import annotations

import itertools
import threading
import weakref
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.discrepancy.trial import lr_of
from airbearing.analysis.shooting import THETA_SLOTS, Fit, ShootingProblem
from airbearing.analysis.shooting.fit import gram, reduced_errors, solve_gram

__all__ = [
    "KEPT_COLUMNS",
    "Columns",
    "Linearisation",
    "Step",
    "forget_columns",
    "linearise",
    "one_value_linearisation",
]


@dataclass(frozen=True, eq=False)
class Step:
    """A candidate's Gauss-Newton step from the current fit (quadratic model, within bounds)."""

    theta: np.ndarray  # chosen parameters then the candidate's, absolute values
    delta: np.ndarray  # (n_delta, n_windows)
    p: np.ndarray
    rss_model: float  # predicted weighted RSS
    rss: float  # weighted RSS of the residual evaluated at the step
    r: np.ndarray
    # the Jacobian at the current fit in [theta; vec(delta)] is [A E, Jd]: the round's
    # parameter columns A (dense) and the window states' columns Jd, both shared by every
    # candidate of the round, and this step's map E of its parameters to A's columns
    A: np.ndarray
    E: np.ndarray
    Jd: sp.csc_matrix
    feasible: bool  # the chosen parameters stay inside their bounds

    @property
    def At(self) -> np.ndarray:
        """The step's parameter columns ``A E`` (made on each call, not kept)."""
        return self.A @ self.E

    @property
    def J(self) -> sp.csc_matrix:
        """The Jacobian at the current fit in ``[theta; vec(delta)]`` (made on each call)."""
        return sp.hstack([sp.csc_matrix(self.At), self.Jd]).tocsc()


class Linearisation:
    """The current fit's residual and Jacobian in every candidate parameter, windows eliminated.

    Parameters
    ----------
    problem : ShootingProblem
    current : Fit
        The current (converged) fit; its first ``S_sel.shape[1]`` parameters are chosen.
    S_sel : ndarray (n_p, k_sel)
        The chosen effects' columns (``p = p_base + S theta``).
    raw : sequence of int
        The Model parameters (indices of ``p``) any candidate moves.
    cand0 : ndarray (k_c,), optional
        The one candidate's ``theta`` at ``current`` (its parameters are in ``current.p``):
        a linearisation at a fit that holds it (:func:`one_value_linearisation`). None: every
        candidate at zero.
    null : Fit, optional
        The fit likelihood ratios are taken against (default ``current``).
    where : str
        Words for the point, in the notes of the candidates judged on it.
    """

    def __init__(self, problem: ShootingProblem, current: Fit, S_sel: np.ndarray, raw, *,
                 cand0=None, null: Fit | None = None,
                 where: str = "the current fit (shared Jacobian)") -> None:  # fmt: skip
        self.problem, self.current = problem, current
        self.cand0 = None if cand0 is None else np.asarray(cand0, dtype=float)
        self.null = current if null is None else null
        self.where = where
        self.S_sel = np.asarray(S_sel, dtype=float)
        self.k_sel = self.S_sel.shape[1]
        self.raw = list(raw)
        # what the columns are made of, to make them again once let go (:class:`Columns`)
        self.made = Columns(problem, current, self.S_sel, self.raw)
        r, A, Jd = self.made.make()
        self.r = r
        self.A = A
        self.Jd = Jd
        nw, n = problem.windows.n, problem.n_win_res
        m = self.A.shape[1]
        G, g = np.zeros((m, m)), np.zeros(m)
        # per window: its rows, the pseudo-inverse of its states' Gram block, and the
        # products the step needs (D^T A and D^T r: nd x m and nd numbers, where D itself,
        # n x nd dense per window, was some 50 MB on an hour of 50 Hz three-axis samples)
        self.blocks = []
        for j in range(nw):
            R = slice(j * n, (j + 1) * n)
            Aj, rj = self.A[R], r[R]
            Dj = self._window(j)
            P = np.linalg.pinv(Dj.T @ Dj, hermitian=True)
            B = Aj.T @ Dj
            Dr = Dj.T @ rj
            G += Aj.T @ Aj - B @ P @ B.T
            g += Aj.T @ rj - B @ P @ Dr
            self.blocks.append((R, P, B.T, Dr))
        self.G, self.g = G, g
        self.rss0 = float(r @ r)
        self._gram, self._lock = None, threading.Lock()

    def _window(self, j: int) -> np.ndarray:
        """Window ``j``'s initial-state columns on its own rows (dense, n x nd)."""
        nd, n = self.problem.n_delta, self.problem.n_win_res
        return self.Jd[j * n : (j + 1) * n, j * nd : (j + 1) * nd].toarray()

    def columns(self, params: tuple, tie: np.ndarray) -> np.ndarray:
        """``E`` (k_sel + len(raw), k_sel + k_c): chosen and candidate parameters -> columns."""
        k_sel, k_c = self.k_sel, tie.shape[1]
        E = np.zeros((self.A.shape[1], k_sel + k_c))
        E[:k_sel, :k_sel] = np.eye(k_sel)
        idx = self.problem.model.index(list(params), "p")
        for row, pi in zip(tie, idx, strict=True):
            E[k_sel + self.raw.index(pi), k_sel:] += row
        return E

    def step(self, E: np.ndarray, lower_sel, upper_sel, lower_c, upper_c) -> Step:
        """The Gauss-Newton step of the chosen and one candidate's parameters (class doc)."""
        k_sel = self.k_sel
        Gc, gc = E.T @ self.G @ E, E.T @ self.g
        k = Gc.shape[0]
        c0 = np.zeros(k - k_sel) if self.cand0 is None else self.cand0
        th0 = np.r_[self.current.theta, c0]
        lo = np.r_[np.full(k_sel, -np.inf), np.asarray(lower_c, dtype=float)] - th0
        hi = np.r_[np.full(k_sel, np.inf), np.asarray(upper_c, dtype=float)] - th0
        d, q = _box_min(Gc, gc, lo, hi)
        theta = th0 + d
        feasible = bool(
            np.all(theta[:k_sel] >= np.asarray(lower_sel, dtype=float))
            and np.all(theta[:k_sel] <= np.asarray(upper_sel, dtype=float))
        )
        pb = self.problem
        nd, nw = pb.n_delta, pb.windows.n
        Ed = E @ d
        delta = self.current.delta.copy()
        for j, (_, P, DA, Dr) in enumerate(self.blocks):  # D^T e, e = r + A E d
            delta[:, j] -= P @ (Dr + DA @ Ed)
        S_sel_c = self.S_all(E)
        p_base = self.current.p - (self.S_sel @ self.current.theta if k_sel else 0.0)
        if self.cand0 is not None:  # the candidate's part of the point, out of the base too
            p_base = p_base - S_sel_c[:, k_sel:] @ self.cand0
        p = p_base + S_sel_c @ theta
        r = pb.residual(delta.reshape(nd, nw), p)
        return Step(theta, delta, p, self.rss0 + q, float(r @ r), r, self.A, E, self.Jd, feasible)

    def lr_at(self, E: np.ndarray, th_c: np.ndarray) -> float:
        """Likelihood ratio with the candidate at ``th_c``, the chosen effects held and every
        window's state refitted by its linear step (one residual): a check away from the
        current fit, where the quadratic model there does not reach."""
        th_c = np.asarray(th_c, dtype=float)
        if not np.all(np.isfinite(th_c)) or not np.any(th_c):
            return 0.0
        S = self.S_all(E)
        move = th_c if self.cand0 is None else th_c - self.cand0
        r = self.problem.residual(self.current.delta, self.current.p + S[:, self.k_sel :] @ move)
        e = r.copy()
        for j, (R, P, _, _) in enumerate(self.blocks):
            Dj = self._window(j)
            e[R] -= Dj @ (P @ (Dj.T @ r[R]))
        return lr_of(self.null, float(e @ e))

    def S_all(self, E: np.ndarray) -> np.ndarray:
        """``S`` of the chosen and the candidate's parameters (n_p, k)."""
        n_p = self.problem.model.n_p
        S_raw = np.zeros((n_p, len(self.raw)))
        S_raw[self.raw, np.arange(len(self.raw))] = 1.0
        return np.hstack([self.S_sel, S_raw]) @ E

    def _shared_gram(self):
        """``(A^T A, M)``: the Gram matrix of the round's parameter columns, and what
        eliminating the window states takes from it, ``M = A^T Jd (Jd^T Jd)^+ Jd^T A``
        with ``Jd``'s columns scaled by their norms as :func:`.theta_errors` scales them
        (made once per linearisation, on the first step judged; every candidate's is
        ``E^T (.) E``)."""
        with self._lock:
            if self._gram is None:
                Jd = sp.csc_matrix(self.Jd)
                cd = np.sqrt(_column_square_sums(Jd))
                cd = np.where(cd > 0, cd, 1.0)
                Dinv = sp.diags(1.0 / cd)
                Fdd = sp.csc_matrix(Dinv @ gram(Jd) @ Dinv)
                AtJd = _transposed_product(Jd, self.A).T / cd  # (m, n_delta nw), scaled
                AA = self.A.T @ self.A
                M = AtJd @ solve_gram(Fdd, AtJd.T) if Fdd.shape[0] else np.zeros_like(AA)
                self._gram = (AA, M)
            return self._gram

    def errors(self, E: np.ndarray, k: int, s2: float):
        """:func:`.theta_errors` of the step's Jacobian ``[A E, Jd]`` (its first ``k``
        columns the parameters) from :meth:`_shared_gram`, without that matrix: on an
        hour of 50 Hz three-axis samples it and its column-scaled copy and Gram pieces were
        some 400 MB per candidate. The same numbers to rounding (the sums taken in
        another order)."""
        AA, M = self._shared_gram()
        Gt = E.T @ AA @ E
        col = np.sqrt(np.maximum(np.diag(Gt), 0.0))
        c = np.where(col > 0, col, 1.0)
        cc = np.outer(c, c)
        Ftt = Gt / cc
        Fr = Ftt - (E.T @ M @ E) / cc
        return reduced_errors(0.5 * (Fr + Fr.T), Ftt, col[:k], s2)

    def fit_of(self, st: Step, k: int) -> Fit:
        """The step as a :class:`Fit` (errors from the Jacobian at the current fit:
        :meth:`errors`)."""
        pb = self.problem
        n_free = k + st.delta.size
        s2 = st.rss / max(pb.n_res - n_free, 1)
        std, cov, reasons = self.errors(st.E, k, s2)
        self.made.expect(st.E)
        return Fit(
            theta=st.theta,
            theta_std=std,
            p=st.p,
            delta=st.delta,
            rss=st.rss,
            n_res=pb.n_res,
            n_free=n_free,
            gap=pb.gap_of_residual(st.r),
            iterations=0,
            status="screened",
            level="screened",
            not_identifiable=reasons,
            cov=cov,
            # the parameter and window states' columns shared with the round, the step's
            # columns made when asked (:func:`.fit_jacobian`)
            extra={"r": st.r, "J_blocks": (st.A, st.E, st.Jd), "J_source": self.made},
        )


class Columns:
    """The round's parameter columns ``A`` and window-state columns ``Jd`` at a fit, made
    (:meth:`make`) and made again when asked once let go (:meth:`columns_of`): a fit
    judged on its step keeps this and its map ``E`` (``extra["J_made"]``,
    :func:`~airbearing.analysis.shooting.fit_jacobian`) instead of the two, which on an
    hour of 50 Hz three-axis samples are some 220 MB per linearisation, kept from the first
    round to the honest errors at the end. The same numbers again: the same point, the
    problem's weighting of then (:meth:`.ShootingProblem.weighting`) and the same
    evaluation. Made again, only the parameter columns a fit's ``E`` reads are kept; the
    last made are kept with the window states' columns (:data:`_KEPT`), one set at a time.
    """

    def __init__(self, problem, current: Fit, S_sel: np.ndarray, raw: list) -> None:
        self.problem, self.S_sel, self.raw = problem, S_sel, list(raw)
        # the point only (not the fit's own row arrays)
        self.current = replace(current, extra={})
        self.weighting = problem.weighting()
        # A's width and memory order (as the screen stacked it before it wrote it in place)
        self.width = S_sel.shape[1] + len(self.raw)
        self.order = _stacked_order(S_sel.shape[1], [len(self.raw)] if self.raw else [])
        # the maps E of the fits made from these columns (:meth:`expect`), weakly: a fit
        # let go (refitted by IPOPT, or its honest errors taken) no longer asks
        self._expected: list = []

    def expect(self, E: np.ndarray) -> None:
        """A fit made from these columns keeps ``E`` (and may ask :meth:`columns_of` for
        it): its columns are made with another's when they fit in :data:`KEPT_COLUMNS`."""
        self._expected.append(weakref.ref(E))

    def _wanted(self, used: np.ndarray) -> np.ndarray:
        """``used`` and the columns of the fits still expected (:meth:`expect`, in their
        order) while the whole stays within :data:`KEPT_COLUMNS`."""
        want = set(used.tolist())
        alive = [E for E in (ref() for ref in self._expected) if E is not None]
        self._expected = [weakref.ref(E) for E in alive]
        for E in alive:
            more = want | set(np.flatnonzero(np.any(E != 0, axis=1)).tolist())
            if len(more) <= KEPT_COLUMNS:
                want = more
        return np.array(sorted(want), dtype=int)

    def make(self, keep=None, states: bool = True):
        """``(r, A, Jd)`` at the fit (:class:`Linearisation`).

        Every candidate parameter in ONE evaluation (a window function of that many slots,
        built once per problem), the chosen and every candidate parameter's columns written
        straight into ``A`` (no sparse copy of them). ``keep``: only those of ``A``'s
        columns (sorted indices; ``A`` is then ``(n_res, len(keep))``), from the same
        evaluation: the same numbers. Without ``states``, ``Jd`` is None (not made).
        """
        problem = self.problem
        n_p, m = problem.model.n_p, self.width
        keep = np.arange(m) if keep is None else np.asarray(keep, dtype=int)
        W = self.weighting[0]
        rows = problem.n_meas + (W.shape[0] if problem.link and W is not None else 0)
        A = np.zeros((rows, keep.size), order=self.order)
        if not self.raw:
            return None, A, None
        S_raw = np.zeros((n_p, len(self.raw)))
        S_raw[self.raw, np.arange(len(self.raw))] = 1.0
        S = np.hstack([self.S_sel, S_raw])
        current = self.current
        at = replace(current, theta=np.r_[current.theta, np.zeros(len(self.raw))])
        r, J, Jd = problem.jacobian_parts(
            at, S, m, right=states, dense=(A, keep, 0), made=self.weighting
        )
        if J is not None:  # (coloured noise with process noise: sparse, then dense)
            J = sp.csc_matrix(J)
            for i, c in enumerate(keep):
                _dense_columns(J, c, c + 1, A, i)
        del J
        return r, A, (sp.csc_matrix(Jd) if states else None)

    def columns_of(self, E: np.ndarray):
        """``(A @ E, Jd)``: a fit's parameter columns (the same numbers to the bit as the
        product with the whole ``A``, :func:`_product`) and the window states' columns.

        Only ``A``'s columns ``E`` reads (its rows not all zero) are made, with those of
        the other fits expected (:meth:`expect`) while they fit in :data:`KEPT_COLUMNS`:
        not every column (on an hour of 50 Hz three-axis samples 16, 9 MB each). ``Jd``
        and the columns made are kept (:data:`_KEPT`) for the next fit of this
        linearisation while one is expected; columns it reads that were not made are made
        again (one more evaluation of the window function: 4.7 s of CPU on that hour),
        ``Jd`` not.
        """
        E = np.asarray(E, dtype=float)
        used = np.flatnonzero(np.any(E != 0, axis=1))
        with _KEPT_LOCK:
            kept = _KEPT[0] if _KEPT[0] is not None and _KEPT[0][0] is self else None
            if kept is None or not np.all(np.isin(used, kept[2])):
                Jd = None if kept is None else kept[1]
                _KEPT[0] = kept = None  # (the last let go before these are made)
                keep = self._wanted(used)
                _, A, Jd_made = self.make(keep=keep, states=Jd is None)
                kept = _KEPT[0] = (self, Jd if Jd is not None else Jd_made, keep, A)
            _, Jd, have, A = kept
            At = _product(A, have, self.width, E, self.order)
            if not self._others(E):  # the last fit expected: let them go after its errors
                _KEPT[0] = None
            return At, Jd

    def _others(self, E) -> bool:
        """Whether a fit other than the one keeping ``E`` is still expected (:meth:`expect`)."""
        return any(ref() is not None and ref() is not E for ref in self._expected)


#: The last :class:`Columns` made again: ``(source, Jd, columns, A[:, columns])``. The
#: honest errors at the end take the first round's candidates one after the other, several
#: from one linearisation.
_KEPT: list = [None]
_KEPT_LOCK = threading.Lock()

#: Parameter columns :meth:`Columns.columns_of` makes at most at once (more only when one
#: fit reads more): a three-axis effect's and one more. Each column is 9 MB held through
#: the honest errors on an hour of 50 Hz three-axis samples, each evaluation of the window
#: function 4.2-4.7 s of CPU there. Measured on that hour (16 columns; the first round's
#: step-judged fits read 13 of them, in 5 sets): 7 made them in 2 evaluations, 4 in 4 and
#: 1 (each fit's own) in 5, the honest errors' peak 188, 171-177 and 163 MB above their
#: start (the whole ``A`` made once: some 240 MB).
KEPT_COLUMNS = 4

#: Rows of ``A`` at a time in :func:`_product` (5 MB for 20 columns).
PRODUCT_ROWS = 1 << 15


def _product(A_have, have, width: int, E, order: str, rows: int = PRODUCT_ROWS) -> np.ndarray:
    """``A @ E`` for an ``A`` of ``width`` columns in memory ``order`` of which only the
    columns ``have`` (``A_have``) are given, ``E`` zero in every other row.

    NumPy's product goes to BLAS, whose sums over ``A``'s columns depend on where the
    terms lie among them (the matrix-vector kernel adds them in SIMD lanes by column
    position: ``A_have @ E[have]`` of a tied column differs in the last bit). So ``A`` is
    made back ``rows`` rows at a time, of its width and order, zero in the columns not
    given (each zero term ``0 * 0`` where ``A``'s was ``a * 0``: a zero either way), and
    multiplied by the whole ``E``: the same kernel on the same positions. Measured on
    random matrices of the hour's size (3 to 30 columns, 1 to 4 of ``E``'s, ties of up to
    6 columns, chunks of 4096 to 32768 rows, C and F order): the same bits as the whole
    product with single-threaded OpenBLAS (Haswell kernels, as the search is measured);
    with 2 threads the whole product's own last bits depend on where BLAS splits the
    rows (one row in a million differed). A zero of the product may come out with the
    other sign; ``A``'s columns not given must be finite (a non-finite one would have made
    the product NaN).
    """
    E = np.asarray(E, dtype=float)
    n = A_have.shape[0]
    out = np.empty((n, E.shape[1]), order="F")  # (the honest errors' order: no copy)
    T = np.zeros((min(rows, n), width), order=order)
    for a in range(0, n, rows):
        b = min(a + rows, n)
        if b - a < T.shape[0]:  # (the last, shorter block: its own contiguous array)
            T = np.zeros((b - a, width), order=order)
        T[:, have] = A_have[a:b]
        out[a:b] = T @ E
    return out


def forget_columns() -> None:
    """Let go of the columns :meth:`Columns.columns_of` made last."""
    with _KEPT_LOCK:
        _KEPT[0] = None


def linearise(problem, current, S_sel, cands) -> Linearisation | None:
    """The round's :class:`Linearisation` for ``cands`` (None when no slot is left)."""
    k_sel = S_sel.shape[1]
    if k_sel >= THETA_SLOTS or not cands:
        return None
    idx = problem.model.index
    raw = list(dict.fromkeys(i for c in cands for i in idx(list(c.params), "p")))
    return Linearisation(problem, current, S_sel, raw)


def one_value_linearisation(problem, current, one, cand, S_sel) -> Linearisation | None:
    """The :class:`Linearisation` of the per-axis ``cand`` at its one-value form's IPOPT fit
    ``one`` (a :class:`Fit` of the chosen effects and the one value), or None.

    The one-value form is the per-axis form with its axes tied, so its fit is a point of
    the per-axis problem: every axis at the one value, the chosen effects and the window
    states as fitted. One Jacobian there in the per-axis parameters makes the per-axis
    form's Gauss-Newton step from that point, which :func:`screened` judges as it judges
    every step (likelihood ratios against the round's ``current`` fit): the quadratic
    model's fall checked by the residual at the step, the far-from-the-best rule, and a
    step whose BIC comes within ``MATTER_BIC`` of the round's best refitted by IPOPT. The
    per-axis form can only add to the one value's likelihood ratio; it adds ``2 ln n`` to
    its BIC penalty (24 on the 10 min seed-004 log), so where the axes agree the step is far
    from mattering. Where they differ (a friction whose axes differ 10-fold) the step from
    the one value is long, the quadratic model less sure, and IPOPT decides as before.

    None when ``one`` keeps no Jacobian, fitted its windows' start yaw (another layout), or
    is not a point of the per-axis form (its parameters are not tied the same way).
    """
    k_sel = S_sel.shape[1]
    if one is None or "J" not in one.extra or one.extra.get("start_yaw"):
        return None
    if k_sel + cand.k > THETA_SLOTS or one.theta.size <= k_sel:
        return None
    n_p = problem.model.n_p
    idx = problem.model.index(list(cand.params), "p")
    S_c = np.zeros((n_p, cand.k))
    S_c[idx] = cand.tie
    # the one value's parameter offsets from the chosen effects' point, in the per-axis form
    dp = one.p - (problem.model.p0 + (S_sel @ one.theta[:k_sel] if k_sel else 0.0))
    th_c0 = np.linalg.lstsq(S_c, dp, rcond=None)[0]
    if not np.allclose(S_c @ th_c0, dp, rtol=0.0, atol=1e-12 * float(np.max(np.abs(dp)))):
        return None
    base = replace(one, theta=np.asarray(one.theta[:k_sel], dtype=float))
    return Linearisation(
        problem, base, S_sel, list(dict.fromkeys(idx)), cand0=th_c0, null=current,
        where="the one-value form's IPOPT fit (its axes tied)",
    )  # fmt: skip


def _transposed_product(J: sp.csc_matrix, A: np.ndarray, width: int = 2) -> np.ndarray:
    """``np.asarray(J.T @ A)`` for a dense ``A`` of ``J``'s rows, ``width`` of ``A``'s
    columns at a time: scipy's product makes a row-major copy of a column-major ``A``
    whole (the screen's parameter columns of a later round: some 120 MB on an hour of
    50 Hz three-axis samples), of a block only this way. Each entry is scipy's sum over
    the same entries in the same order (its product of several columns at once takes each
    column's sums alone)."""
    if A.flags.c_contiguous or A.shape[1] <= width:
        return np.asarray(J.T @ A)
    Jt = J.T
    return np.hstack([np.asarray(Jt @ A[:, a : a + width]) for a in range(0, A.shape[1], width)])


def _column_square_sums(J: sp.csc_matrix, blocks: int = 16) -> np.ndarray:
    """``J.power(2).sum(axis=0)`` of a CSC ``J`` (each column's sum of its own entries, in
    their order: the same numbers), a block of columns at a time instead of a squared copy
    of the whole matrix (some 100 MB for the window states' columns on an hour of 50 Hz
    three-axis samples)."""
    n = J.shape[1]
    edges = np.unique(np.r_[np.arange(0, n, max(1, -(-n // blocks))), n])
    return np.concatenate(
        [np.zeros(0)]
        + [
            np.asarray(J[:, a:b].power(2).sum(axis=0)).ravel()
            for a, b in zip(edges[:-1], edges[1:], strict=True)
        ]
    )


def _stacked_order(k_sel: int, sizes: list) -> str:
    """The memory order NumPy gives ``np.hstack`` of the dense copies of a CSC matrix's
    ``k_sel`` columns and chunks of ``sizes`` columns (as the screen stacked them before it
    wrote them in place): BLAS's products round alike only on the same layout."""
    probe = np.hstack([sp.csc_matrix((2, c)).toarray() for c in (k_sel, *sizes)])
    return "C" if probe.flags.c_contiguous else "F"


def _dense_columns(J: sp.csc_matrix, c0: int, c1: int, out: np.ndarray, o0: int) -> None:
    """Columns ``c0:c1`` of ``J`` added into the zeros of ``out[:, o0:]``: the numbers of
    ``J[:, c0:c1].toarray()`` (which adds each entry to a zero), without that copy."""
    for c in range(c0, c1):
        a, b = J.indptr[c], J.indptr[c + 1]
        out[J.indices[a:b], o0 + c - c0] += J.data[a:b]


def _box_min(G: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """``argmin 2 g.d + d.G.d`` over ``lo <= d <= hi`` and its value (active sets, k <= 6).

    Columns are scaled by the diagonal; a direction the data do not see (zero column) stays 0.
    """
    k = g.size
    c = np.sqrt(np.maximum(np.diag(G), 0.0))
    seen = c > 0
    c = np.where(seen, c, 1.0)
    Gs, gs = G / np.outer(c, c), g / c
    los, his = lo * c, hi * c
    bounded = [i for i in range(k) if np.isfinite(los[i]) or np.isfinite(his[i])]
    best, best_q = np.zeros(k), 0.0  # d = 0 (the current fit) is inside the box
    for pick in itertools.product((None, "lo", "hi"), repeat=len(bounded)):
        d = np.zeros(k)
        fixed = ~seen
        for i, how in zip(bounded, pick, strict=True):
            if how is not None:
                d[i], fixed[i] = (los[i] if how == "lo" else his[i]), True
        if not np.all(np.isfinite(d)):
            continue
        free = ~fixed
        if free.any():
            rhs = -(gs[free] + Gs[np.ix_(free, fixed)] @ d[fixed])
            d[free] = np.linalg.pinv(Gs[np.ix_(free, free)], hermitian=True) @ rhs
        tol = 1e-12 * (1 + np.abs(d))
        if np.any(d < los - tol) or np.any(d > his + tol):
            continue
        q = float(2 * gs @ d + d @ Gs @ d)
        if q < best_q:
            best, best_q = d, q
    return best / c, best_q
