"""The continuity defects of linked windows penalised at a given process-noise intensity.

What one fit at one intensity needs, below :class:`.ShootingProblem` (which solves with
:func:`penalised_solver` when its ``penalty`` is set) and :mod:`.process_noise` (which
chooses the intensity): the scale of the intensity (:data:`KAPPA_GRID`,
:func:`piece_durations`), the whitening ``W`` of the defects (:func:`defect_whitening`,
:func:`set_intensity`) and IPOPT on the stacked residual ``[r; W c]``. The model of the
defects (an integrated Wiener process) is stated in :mod:`.process_noise`.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.fit import PINV_RCOND
from airbearing.analysis.shooting.function_cache import borrowed
from airbearing.analysis.shooting.functions import (
    _Call,
    _problem_functions,
    delta_layout,
    evaluate,
    ipopt_options,
    layout_key,
    scale_columns,
    vstack_csc,
)
from airbearing.analysis.shooting.sparse import gram, let_go

__all__ = [
    "KAPPA_GRID",
    "defect_whitening",
    "hessian_pattern",
    "penalised_solver",
    "piece_durations",
    "set_intensity",
    "start_yaw_profiled",
]

#: Grid of the dimensionless intensity ``kappa`` (defect variance over a typical piece, in
#: units of the measurement noise variance), searched from the top down. 1e4: the windows
#: are practically free (the old fixed-window fit); 1e-8: one trajectory per segment (a
#: defect of 1e-4 noise sigma; lower intensities only make the solve ill-conditioned).
KAPPA_GRID = (1e4, 1e2, 1.0, 1e-2, 1e-4, 1e-6, 1e-8)

# ----------------------------------------------------------------------------
# the whitening of the defects


def piece_durations(problem) -> np.ndarray:
    """s, time from each window's first row to its hand-over row."""
    w = problem.windows
    cum = np.concatenate([np.zeros((w.n, 1)), np.cumsum(w.dt, axis=1)], axis=1)
    end = np.asarray(w.end, dtype=int)
    return cum[np.arange(w.n), end]


def _sigma_of_kappa(problem, kappa: float) -> float:
    """``sigma_w`` of a dimensionless intensity (:mod:`.process_noise`)."""
    T = float(np.mean(piece_durations(problem)[:-1])) if problem.windows.n > 1 else 1.0
    if problem.attitude_measured:
        return math.sqrt(kappa * problem.sigma_att**2 * 3.0 / T**3)
    return math.sqrt(kappa * problem.sigma_rate**2 / T)


def wheel_axes_on_rate(problem) -> np.ndarray:
    """``(n_ws, n_rate)``: each compared wheel's spin axis on the fitted rate axes (body
    axes; dof 1: ``+-1`` on ``wz``); no rows when the wheel speeds are not compared."""
    if not problem.n_ws:
        return np.zeros((0, problem.n_rate))
    axes = np.asarray(problem.model.testbed.wheels.axes, dtype=float)
    return axes if problem.n_rate == 3 else axes[:, 2:3]


def defect_whitening(problem, sigma_w: float):
    """``(W, logdet_W)``: the whitening of every consecutive pair's defects (:mod:`.process_noise`).

    Parameters
    ----------
    problem : ShootingProblem
        On linked windows.
    sigma_w : float
        Random-walk intensity of the rate, rad/s per sqrt(s) (> 0).

    Returns
    -------
    W : scipy.sparse.csr_matrix (n_delta (n - 1), n_delta (n - 1))
        Maps the defects (noise units, :func:`.problem_functions._link_function`) to independent
        unit-variance residuals; zero rows where two windows are not linked.
    logdet : float
        ``log det`` of the linked blocks of ``W``.
    """
    w = problem.windows
    nd, n_att, n_rate = problem.n_delta, problem.n_att, problem.n_rate
    T = piece_durations(problem)
    link = np.asarray(w.link, dtype=bool)
    sa, sr = problem.sigma_att, problem.sigma_rate
    ws_rows = wheel_axes_on_rate(problem)
    sw = problem.sigma_ws_axes if len(ws_rows) else None  # each wheel's own level
    rows, cols, vals = [], [], []
    logdet = 0.0
    eps = 1e-12  # keeps a block positive definite at any intensity
    for j in np.flatnonzero(link):
        base = j * nd
        t = max(float(T[j]), 1e-9)
        q = sigma_w**2
        joint = n_att and problem.attitude_measured
        if n_att and not joint:
            # a dof-1 gyro log's yaw, fitted at the starts but not measured
            # (:func:`.delta_layout`): one yaw trajectory per segment, its defect weighed as
            # a measurement at the replay's attitude resolution (``sigma_att``) whatever the
            # intensity, so the rate's likelihood stays what it was without it
            rows.append(base)
            cols.append(base)
            vals.append(1.0)
        for a in range(n_rate):
            ir = base + n_att + a
            vr = q * t / sr**2 + eps
            if joint:
                ia = base + a
                va = q * t**3 / 3.0 / sa**2 + eps
                cv = q * t**2 / 2.0 / (sa * sr)
                # inverse of the lower Cholesky factor of [[va, cv], [cv, vr]]
                l11 = math.sqrt(va)
                l21 = cv / l11
                l22 = math.sqrt(max(vr - l21**2, eps))
                rows += [ia, ir, ir]
                cols += [ia, ia, ir]
                vals += [1.0 / l11, -l21 / (l11 * l22), 1.0 / l22]
                logdet -= math.log(l11 * l22)
            else:
                rows.append(ir)
                cols.append(ir)
                vals.append(1.0 / math.sqrt(vr))
                logdet -= 0.5 * math.log(vr)
        for i, coef in enumerate(ws_rows):
            # a wheel's ABSOLUTE speed W_i + a_i . w: a torque on the body turns body and
            # wheel together and leaves it alone (FORMATS.md: only the wheel's own torques
            # change it), so its defect is the wheel's own unexplained torque, a random walk
            # of the same dimensionless intensity as the rate's (defect variance over the
            # wheel speeds' noise variance): nearly free pieces at the top of the grid, one
            # absolute wheel-speed trajectory per segment at its bottom
            iw = base + n_att + n_rate + i
            vw = q * t / sr**2 + eps
            rows.append(iw)
            cols.append(iw)
            vals.append(1.0 / math.sqrt(vw))
            logdet -= 0.5 * math.log(vw)
            for a in range(n_rate):
                if coef[a] != 0.0:
                    rows.append(iw)
                    cols.append(base + n_att + a)
                    vals.append(coef[a] * sr / sw[i] / math.sqrt(vw))
        for i in range(n_att + n_rate + len(ws_rows), nd):  # lagged gyro states: like the rate
            vr = q * t / sr**2 + eps
            rows.append(base + i)
            cols.append(base + i)
            vals.append(1.0 / math.sqrt(vr))
            logdet -= 0.5 * math.log(vr)
    m = nd * max(w.n - 1, 0)
    W = sp.csr_matrix((vals, (rows, cols)), shape=(m, m))
    return W, logdet


def start_yaw_profiled(problem, G):
    """The window states' information ``G`` (``n_delta n_windows`` square, window-major) with
    a dof-1 gyro log's start yaws profiled out; ``G`` itself on any other problem.

    The start yaws are fitted but not measured (:func:`.delta_layout`) and held to one
    trajectory per segment by their defects (:func:`defect_whitening`); when no torque
    depends on the yaw at the fitted parameters their common offset is in nothing and
    ``G`` is singular. The Schur complement (a pseudo-inverse) leaves the information of
    the other window states, which is then what it is without the start yaws.

    Returns
    -------
    scipy.sparse.csc_matrix
        ``G``, or the other states' block less what the yaws explain (``n_delta - 1``
        entries per window).
    """
    if not (problem.n_att and not problem.attitude_measured):
        return G
    nd, nw = problem.n_delta, problem.windows.n
    yaw = np.arange(nw) * nd
    rest = np.setdiff1d(np.arange(nd * nw), yaw)
    G = sp.csc_matrix(G)
    Gyy = G[yaw][:, yaw].toarray()
    Gyr = G[yaw][:, rest].toarray()
    explained = Gyr.T @ np.linalg.pinv(Gyy, rcond=PINV_RCOND, hermitian=True) @ Gyr
    schur = G[rest][:, rest].toarray() - explained
    return sp.csc_matrix(0.5 * (schur + schur.T))


# ----------------------------------------------------------------------------
# the solver: linked windows, defects penalised


class _PenalisedOracle:
    """Stacked residual ``[r; W c]`` and its Jacobian at the last iterate.

    ``raw``: the window Jacobian's own output ``(rm, Jm, c, Jc)`` of the last iterate's
    ``(r, J)`` (before the whitening and the column scaling), kept when ``keep_raw`` is set
    (:meth:`.ShootingProblem.fit` hands it to the next fit from the same point)."""

    def __init__(self, fr, fj, n_v: int) -> None:
        self.fr, self.fj, self.n_v = fr, fj, n_v
        self.z = self.r = self.J = self.raw = self.C = None
        self.keep_raw, self.used = False, None

    def set(self, p_base, S, scale, data, W, P=None, keep_raw=False, used=None) -> None:
        """The next solve's point and weighting; ``used``: the parameter slots it frees
        (the others' columns left empty: :class:`.problem_functions.WindowJacobian`)."""
        self.pb, self.S, self.scale, self.data, self.W = p_base, S, scale, data, W
        self.used = used
        self.P = P  # whitening of the measurement rows (coloured noise), or None
        self.keep_raw = keep_raw
        self.z = self.raw = None

    def prime(self, z, raw) -> None:
        """``(r, J)`` at ``z`` from the window Jacobian's output ``raw`` there (the fit's
        start, evaluated already for its column scaling): IPOPT's first iterate then costs
        no evaluation."""
        self.z = np.array(z, dtype=float)
        self._stack(raw)

    def release(self) -> None:
        """Forget the last iterate (its Jacobian is large on long logs; the cached solver
        keeps this oracle)."""
        self.z = self.r = self.J = self.raw = self.C = None
        if hasattr(self, "Jc"):
            self.c = self.Jc = None

    def _stack(self, raw, fresh: bool = False) -> None:
        """``(r, J)`` of the window Jacobian's output ``raw``; ``fresh``: evaluated here for
        this iterate only (not kept, nor a fit's start, which the problem may keep): its
        measurement rows' arrays are let go as the stacked ones are made."""
        rm, Jm, c, Jc = raw
        self.raw = raw if self.keep_raw else None
        own = fresh and not self.keep_raw
        self.C = Jc  # the defects' own Jacobian (small): the errors' linearised problem
        if self.P is not None:
            rm, PJm = self.P @ rm, self.P @ Jm
            if own:  # (its indices: the window Jacobian's own, kept for every iterate)
                let_go(Jm, values_only=True)
            Jm, own = PJm, True
        self.r = np.r_[rm, self.W @ c]
        self.J = scale_columns(vstack_csc(Jm, self.W @ Jc, consume=own), self.scale)

    def r_at(self, z):
        if self.z is None or not np.array_equal(z, self.z):
            rm, c = evaluate(self.fr, z * self.scale, self.pb, self.S, self.data)
            self.z, self.J, self.raw, self.C = z.copy(), None, None, None
            self.r = np.r_[rm if self.P is None else self.P @ rm, self.W @ c]
        return self.r

    def rj_at(self, z):
        if self.z is None or self.J is None or not np.array_equal(z, self.z):
            # the last iterate's Jacobian let go before this one is made (it was held
            # beside the window Jacobian and its stacked copy while they were made)
            self.z = self.r = self.J = self.raw = self.C = None
            raw = self.fj(z * self.scale, self.pb, self.S, self.data, used=self.used)
            self.z = z.copy()
            self._stack(raw, fresh=True)
        return self.r, self.J


class StackedPart:
    """The parameter columns ``theta`` and every window's own columns of a
    :class:`~.problem_functions.WindowJacobian` on linked windows written straight into the
    arrays of their stack over the whitened defects' rows ``B = (W Jc)[:, those columns]``
    (:func:`.sparse.vstack_csc`'s layout), room left for ``B``'s entries by the structure
    of ``|W|`` times that of ``Jc`` (a superset of ``B``'s): no copy of the part to stack it
    (on an hour of 50 Hz three-axis samples the part and the stacked values, 130 MB, were
    held at once). A part of the window Jacobian's call (``parts``), filled window block by
    window block; :meth:`stacked` then puts ``B``'s values in (the same arrays as
    ``vstack_csc(part, B)``)."""

    def __init__(self, fj, theta, W) -> None:
        th = np.asarray(theta, dtype=int)
        nw, K, m = fj.nw, fj.K, fj.shape[0]
        Bp = sp.csc_matrix(abs(sp.csr_matrix(W)) @ _pattern(fj.defect_sparsity()))
        Bp = Bp[:, np.r_[th, np.arange(K, fj.shape[1])]]
        Bp.sort_indices()
        n_cols = Bp.shape[1]
        ind, ptr = fj.index_arrays(th, True)
        self.spans = fj.block_spans(th, True)
        col = np.repeat(np.arange(n_cols), np.diff(Bp.indptr))
        self.places = ptr[col + 1].astype(np.int64) + np.arange(Bp.nnz, dtype=np.int64)
        total = ind.size + Bp.nnz
        big = max(m + Bp.shape[0], total) >= np.iinfo(np.int32).max
        itype = np.int64 if big else np.int32
        rest = np.ones(total, dtype=bool)
        rest[self.places] = False
        self.indices = np.empty(total, dtype=itype)
        self.indices[self.places] = Bp.indices.astype(itype) + itype(m)
        self.indices[rest] = ind
        del ind, rest
        self.indptr = ptr.astype(itype) + Bp.indptr.astype(itype)
        self.data = np.empty(total)
        self.shape = (m + Bp.shape[0], n_cols)
        self.Bp = Bp
        # where each span's entries start without B's (as in the part alone), and how far
        # B's entries before a column move that column's: each parameter column's alike,
        # each window's own columns by their own (t: the column of each block entry)
        sizes = [(b - a) * nw for a, b in self.spans]
        self.starts = np.r_[0, np.cumsum(sizes)[:-1]].astype(np.int64)
        shift = Bp.indptr.astype(np.int64)
        self.shift_theta = shift[: th.size]
        nd = (fj.shape[1] - K) // nw
        self.shift_windows = shift[th.size : th.size + nd * nw].reshape(nw, nd)
        self.t = np.repeat(np.arange(nd), fj.window_column_counts())
        self.e = np.arange(self.t.size, dtype=np.int64)

    def fill(self, blocks: np.ndarray, j0: int) -> None:
        """Windows ``j0 : j0 + len(blocks)`` from their blocks' nonzeros (one row each)."""
        n = blocks.shape[0]
        last = len(self.spans) - 1
        for i, ((a, b), at) in enumerate(zip(self.spans, self.starts, strict=True)):
            w = b - a
            if i < last:  # a parameter column: every window's rows in turn
                o = at + self.shift_theta[i] + j0 * w
                self.data[o : o + n * w].reshape(n, w)[...] = blocks[:, a:b]
            else:
                j = np.arange(j0, j0 + n, dtype=np.int64)
                dest = (at + j * w)[:, None] + self.e[None, :]
                dest += self.shift_windows[j0 : j0 + n][:, self.t]
                self.data[dest] = blocks[:, a:b]

    def matrix(self) -> None:
        """Nothing yet: :meth:`stacked` once ``B`` is known."""
        return None

    def stacked(self, B: sp.csc_matrix) -> sp.csc_matrix:
        """``[part; B]`` in this part's arrays, ``B`` the defects' rows of its columns (the
        slots left for entries ``B`` has not, exact zeros its product dropped, taken out);
        stacked anew if ``B`` has entries outside the room left (a NaN's product)."""
        B = sp.csc_matrix(B)
        B.sort_indices()
        Bp, n_r = self.Bp, self.Bp.shape[0]
        if B.shape != Bp.shape:  # pragma: no cover - programming error
            raise ValueError("StackedPart: the defects' rows have another shape")
        cols = np.arange(Bp.shape[1], dtype=np.int64)
        key_p = np.repeat(cols, np.diff(Bp.indptr)) * n_r + Bp.indices
        key_b = np.repeat(cols, np.diff(B.indptr)) * n_r + B.indices
        present = np.isin(key_p, key_b)
        if int(present.sum()) != B.nnz:  # (a NaN's product): the part alone, stacked anew
            rest = np.ones(self.data.size, dtype=bool)
            rest[self.places] = False
            part = sp.csc_matrix(
                (self.data[rest], self.indices[rest], self.indptr - Bp.indptr),
                shape=(self.shape[0] - n_r, self.shape[1]),
            )
            self.data = self.indices = None
            return vstack_csc(part, B, consume=True)
        self.data[self.places[present]] = B.data
        n = self.data.size
        gone = self.places[~present]
        if gone.size:  # each later entry moves left by the slots before it
            per_col = np.bincount(
                np.repeat(cols, np.diff(Bp.indptr))[~present], minlength=cols.size
            )
            for arr in (self.data, self.indices):
                _drop_slots(arr, gone)
            self.indptr = self.indptr - np.r_[0, np.cumsum(per_col)].astype(self.indptr.dtype)
            n -= gone.size
        data, indices = self.data[:n], self.indices[:n]
        self.data = self.indices = None
        return sp.csc_matrix((data, indices, self.indptr), shape=self.shape, copy=False)


#: Most entries moved at once by :func:`_drop_slots` (its temporary copy: 8 MB).
DROP_BLOCK_ENTRIES = 1 << 20


def _drop_slots(arr: np.ndarray, gone: np.ndarray) -> None:
    """Take the entries at the sorted positions ``gone`` out of ``arr`` in place: the others
    moved left (in order) to its first ``arr.size - gone.size`` entries."""
    bounds = np.r_[gone, arr.size]
    start = 0
    for i, end in enumerate(bounds):  # entries start:end move left by i
        a = int(start)
        while i and a < end:
            b = min(a + DROP_BLOCK_ENTRIES, int(end))
            arr[a - i : b - i] = arr[a:b].copy()
            a = b
        start = end + 1


def _pattern(spy: ca.Sparsity) -> sp.csc_matrix:
    """A CasADi sparsity as a scipy CSC matrix of ones."""
    return sp.csc_matrix(
        (np.ones(spy.nnz()), np.asarray(spy.row()), np.asarray(spy.colind())),
        shape=(spy.size1(), spy.size2()),
    )


def hessian_pattern(fj, nd: int, nw: int) -> sp.csc_matrix:
    """Upper triangle of the structure of ``J^T J + Jc^T W^T W Jc`` (``fj`` the problem's
    :class:`~.problem_functions.WindowJacobian`; ``W`` dense within each pair's ``nd x nd`` block):
    fixed for a problem structure, so IPOPT gets a sparse Hessian (the window states couple
    only their neighbours).

    Made from one window's block (every window's rows have its structure, on the parameter
    columns and on their own window's states), not from ``J``'s: the same CSC arrays as
    ``triu(J^T J + ...)`` of ``J``'s pattern (sorted indices, ones), without that pattern
    and its product (on an hour of 50 Hz three-axis samples 6.5 million entries, some
    150 MB at each penalised solver's build).
    """
    K, n_v = fj.K, fj.shape[1]
    B = _pattern(fj.win_rj.sparsity_out(1))  # one window's rows: (m, K + nd)
    G = sp.coo_matrix(B.T @ B)  # a row's columns pair up in its window's block only
    off = (np.arange(nw, dtype=np.int64) * nd)[:, None]
    gr, gc = G.row.astype(np.int64), G.col.astype(np.int64)
    rows = [np.where(gr < K, gr, gr + off).ravel()]  # window j's states at K + j nd
    cols = [np.where(gc < K, gc, gc + off).ravel()]
    if nw > 1:  # the defects: each pair's rows mixed by its block of W
        Jc = _pattern(fj.defect_sparsity())
        Wp = sp.block_diag([np.ones((nd, nd))] * (nw - 1), format="csc")
        D = sp.coo_matrix((Wp @ Jc).T @ (Wp @ Jc))
        rows.append(D.row.astype(np.int64))
        cols.append(D.col.astype(np.int64))
    row, col = np.concatenate(rows), np.concatenate(cols)
    upper = row <= col
    keys = np.unique(col[upper] * n_v + row[upper])  # column-major, rows sorted
    indptr = np.r_[0, np.cumsum(np.bincount(keys // n_v, minlength=n_v))]
    itype = np.int32 if max(n_v, keys.size) < np.iinfo(np.int32).max else np.int64
    H = sp.csc_matrix(
        (np.ones(keys.size), (keys % n_v).astype(itype), indptr.astype(itype)),
        shape=(n_v, n_v),
    )
    H.has_sorted_indices = True
    return H


def _build_penalised(model, L, nw, K, outputs, substeps, jit, max_iter, objective_stop=False):
    fr, fj, _ = _problem_functions(model, L, nw, K, outputs, substeps, jit, True)
    nd = sum(delta_layout(model, outputs))
    n_v = K + nd * nw
    o = _PenalisedOracle(fr, fj, n_v)
    Hp = hessian_pattern(fj, nd, nw)
    h_spy = ca.Sparsity(n_v, n_v, Hp.indptr.tolist(), Hp.indices.tolist())
    h_rows = Hp.indices
    h_cols = np.repeat(np.arange(n_v), np.diff(Hp.indptr))

    # a trial step far out (a candidate's wild iterate) may overflow: IPOPT takes the
    # infinite objective as a failed step and backtracks, nothing to warn about
    def f(z):
        r = o.r_at(z)
        with np.errstate(over="ignore", invalid="ignore"):
            return [0.5 * float(r @ r)]

    def grad(z, _par):
        r, J = o.rj_at(z)
        with np.errstate(over="ignore", invalid="ignore"):
            return [0.5 * float(r @ r), np.asarray(J.T @ r).ravel()]

    def hess(z, _par, lam_f, _lam_g):
        _, J = o.rj_at(z)
        # scipy's J.T @ J makes a CSR copy of the whole J first (on an hour of 50 Hz
        # three-axis samples 87 MB at each Hessian, the peak of a candidate's IPOPT fit);
        # gram: the same sums, block of columns by block
        H = gram(J).tocsr()
        vals = float(lam_f[0]) * np.asarray(H[h_rows, h_cols]).ravel()
        return [ca.DM(h_spy, vals)]

    f_jac = _Call(
        "pn_jac_f", [n_v, 1], [ca.Sparsity.dense(1, n_v)], lambda z, _f: [grad(z, 0)[1][None, :]]
    )
    F = _Call("pn_f", [n_v], [ca.Sparsity.dense(1, 1)], f, lambda name: f_jac)
    GF = _Call("pn_grad_f", [n_v, 0], [ca.Sparsity.dense(1, 1), ca.Sparsity.dense(n_v, 1)], grad)
    H = _Call("pn_hess_l", [n_v, 0, 1, 0], [h_spy], hess)
    z = ca.MX.sym("z", n_v)
    solver = ca.nlpsol(
        "output_error_process_noise",
        "ipopt",
        {"x": z, "f": F(z)},
        {
            "grad_f": GF,
            "hess_lag": H,
            **ipopt_options(max_iter, objective_stop),
        },
    )
    return solver, (F, GF, H, f_jac, o)


def penalised_solver(model, L, nw, K, outputs, substeps, jit, max_iter, objective_stop=False):
    """``with penalised_solver(...) as (solver, keep)``: IPOPT on the stacked residual
    ``[r; W c]`` (:mod:`.process_noise`), lent by the one bounded cache
    (:func:`.function_cache.borrowed`); ``objective_stop`` as :func:`.solver.ipopt_options`."""
    args = (model, L, nw, K, outputs, substeps, jit, max_iter, objective_stop)
    key = ("penalised", layout_key(model, outputs), *args[1:])
    return borrowed(key, lambda: _build_penalised(*args))


def set_intensity(problem, kappa: float | None) -> None:
    """Penalise ``problem``'s defects at dimensionless intensity ``kappa`` (None: unpenalised)."""
    if kappa is None:
        problem.penalty, problem.penalty_logdet, problem.process_noise = None, 0.0, None
        return
    sigma_w = _sigma_of_kappa(problem, kappa)
    problem.penalty, problem.penalty_logdet = defect_whitening(problem, sigma_w)
    problem.process_noise = (float(kappa), float(sigma_w))
