"""The compiled functions of ALL windows of a problem: the residual (with the continuity
defects of linked windows), its Jacobian (:class:`WindowJacobian`) and the outputs.

The window functions of :mod:`.window_functions` mapped over the windows, ``THREADS`` at a
time (:func:`map_windows`); the Jacobian's blocks written straight into NumPy and placed in
a scipy CSC matrix. Cached in the one bounded cache (:mod:`.function_cache`).
"""

from __future__ import annotations

import weakref

import casadi as ca
import numpy as np
import scipy.sparse as sp

from airbearing import quaternion as quat
from airbearing.analysis.shooting.buffers import evaluate, function_buffer
from airbearing.analysis.shooting.function_cache import cached
from airbearing.analysis.shooting.sparse import csc_of
from airbearing.analysis.shooting.window_functions import (
    _window_functions,
    delta_layout,
    layout_key,
    sigma_size,
    start_function,
)
from airbearing.models.model import Model


def _link_function(model: Model, K: int, outputs: tuple) -> ca.Function:
    """Continuity defect between a window's end and the next window's start.

    ``(x_end, dx_end, delta_next, x_meas_next, sigma) -> (c, dc/d[theta; delta], dc/d delta_next)``
    with ``dx_end`` the end state's Jacobian in ``[theta; delta]`` of its own window. One
    entry per entry of ``delta`` (the states a window's ``delta`` sets): the small rotation
    ``2 vec(conj(q_end) (x) q_next)`` (dof 3) or the yaw difference, over ``sigma_att``; the
    rate and lagged-rate differences over ``sigma_rate``, each wheel speed's over its own
    ``sigma`` (defects in noise units).
    """
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    nx = model.nx
    xe = ca.SX.sym("x_end", nx)
    dxe = ca.SX.sym("dx_end", nx, K + nd)
    dn = ca.SX.sym("delta_next", nd)
    xm = ca.SX.sym("x_meas_next", nx - n_lag)
    sig = ca.SX.sym("sigma", sigma_size(model, outputs))
    xn = start_function(model, outputs)(dn, xm)
    rate = list(range(4, 7)) if model.dof == 3 else [1]
    parts = []
    if model.dof == 3:
        e = quat.qmul(quat.qconj(xe[0:4]), xn[0:4])
        parts.append(2 * ca.sign(e[0] + 1e-300) * e[1:4] / sig[1])
    elif n_att:
        parts.append((xn[0] - xe[0]) / sig[1])
    parts.append((xn[rate] - xe[rate]) / sig[0])
    if n_ws:  # the wheel speeds over their own noise level
        ws = list(range(nx - n_lag - n_ws, nx - n_lag))
        parts.append((xn[ws] - xe[ws]) / sig[2:])
    if n_lag:
        lag = list(model.lag_index)
        parts.append((xn[lag] - xe[lag]) / sig[0])
    c = ca.vertcat(*parts)
    return ca.Function(
        "link",
        [xe, dxe, dn, xm, sig],
        [c, ca.mtimes(ca.jacobian(c, xe), dxe), ca.jacobian(c, dn)],
    )


def _data_shapes(
    model: Model, L: int, nw: int, na: int, link: bool = False, n_sigma: int = 2
) -> list:
    """Pieces of the data vector; ``sigma`` (``n_sigma``: 2, or 2 + one per wheel with the
    wheel speeds compared) is always the last one. ``na``: the rows of the measured rates, then the
    measured wheel speeds when they are compared."""
    nx_plant = model.nx - len(model.lag_index)
    return [
        (nx_plant, nw),
        (model.nu, L * nw),
        (1, (L - 1) * nw),
        (1, L * nw),
        (na, L * nw),
        (4, L * nw),
        (1, L * nw),
        *([(1, L * nw)] if link else []),  # end-row selector of each window
        (n_sigma, 1),
    ]


def _problem_functions(model, L, nw, K, outputs, substeps, jit, link=False):
    """``(fr, fj, fy)`` of :func:`_build_problem`, from the one bounded cache."""
    key = ("problem", layout_key(model, outputs), L, nw, K, outputs, substeps, jit, link)
    return cached(key, lambda: _build_problem(model, L, nw, K, outputs, substeps, jit, link))


def residual_function(model, L, nw, K, outputs, substeps, jit, link=False) -> ca.Function:
    """The :class:`WindowResidual` ``fr`` of :func:`_problem_functions` as one CasADi
    Function of all windows (:func:`_residual_graph`): ``(v, p_base, S, data) ->`` the
    residual (and with ``link`` the continuity defects). With ``jit=False`` it is built
    on the symbolic sample step, so CasADi differentiates it in every input (the data
    too)."""
    key = ("residual graph", layout_key(model, outputs), L, nw, K, outputs, substeps, jit, link)
    return cached(key, lambda: _residual_graph(model, L, nw, K, outputs, substeps, jit, link))


def window_jacobian(model, L, nw, K, outputs, substeps, jit, link=False) -> WindowJacobian:
    """The :class:`WindowJacobian` ``fj`` of :func:`_problem_functions`."""
    return _problem_functions(model, L, nw, K, outputs, substeps, jit, link)[1]


def _where_of(nd: int, K: int, shapes: list, nw: int) -> list:
    """Where each input of a window function (``win_r``, ``win_rj``: :func:`_build_problem`'s
    ``args``) lives: ``(source, offset, entries per window or None when shared)``; sources
    0 ``v``, 1 ``p_base``, 2 ``S``, 3 the data vector (its pieces: :func:`_data_shapes`)."""
    pieces, off = [], 0
    for a, b in shapes:
        pieces.append((off, a * b // nw if b % nw == 0 and b >= nw else None))
        off += a * b
    x0, U, dt, wt, W, Q, YW, *rest = pieces
    sigma = rest[-1]
    where = [
        (0, K, nd),
        (3, *x0),
        (3, *U),
        (3, *dt),
        (3, *wt),
        (3, *W),
        (3, *Q),
        (3, *YW),
        (1, 0, None),
        (2, 0, None),
        (0, 0, None),
        (3, sigma[0], None),
    ]
    if len(rest) == 2:  # the hand-over row selector of linked windows
        where.append((3, *rest[0]))  # fmt: skip
    return where


def _sources(v, p_base, S, data) -> list:
    """The four inputs of the functions of all windows as flat float64 arrays (Fortran
    order), what :meth:`_WindowCalls._windows` slices."""
    return [np.ascontiguousarray(np.asarray(a, dtype=float).reshape(-1, order="F"))
            for a in (v, p_base, S, data)]  # fmt: skip


class _WindowCalls:
    """A window function run on all windows from NumPy: ``THREADS`` windows at a time (a
    threaded map of ``THREADS``), each call writing straight into its windows' slices of
    the outputs (:meth:`casadi.Function.buffer`).

    No CasADi expression of all the windows: on an hour of 50 Hz three-axis samples the
    mapped residual and outputs of all windows held ~150 MB of patterns (the data vector's
    and its pieces', one entry each) per slot count and Model, and their evaluations work
    vectors of 65-75 MB each, made for every call."""

    def __init__(self, fn: ca.Function, nw: int, where: list) -> None:
        self.fn, self.nw, self._where = fn, nw, where
        self.pair = fn.map(THREADS, "thread", THREADS) if nw >= THREADS else None
        #: the functions' buffers kept between evaluations (:func:`.buffers.function_buffer`)
        #: for few windows; made for each evaluation of many (:data:`KEPT_BUFFER_WINDOWS`)
        self.keeps_buffers = nw < KEPT_BUFFER_WINDOWS

    def _windows(self, src: list, sink=None) -> list:
        """Every output of the window function for all windows, window after window.

        ``sink``: called ``sink(j0, j1, blocks)`` with the Jacobian blocks' nonzeros of
        windows ``j0:j1`` (``(j1 - j0, nnz)``), :data:`CHUNK_WINDOWS` windows at a time,
        instead of that output kept for all windows (its place in the result: None)."""
        f = self.fn
        out = [
            None if (i == 1 and sink is not None) else np.empty(f.nnz_out(i) * self.nw)
            for i in range(f.n_out())
        ]
        n1 = f.nnz_out(1) if f.n_out() > 1 else 0
        chunk = np.empty(n1 * min(CHUNK_WINDOWS, self.nw)) if sink is not None else None
        c0 = 0  # first window of the chunk in progress
        buffers: dict = {}
        # shared inputs (parameters, noise levels) once per mapped window
        shared = {
            i: src[s][off : off + f.nnz_in(i)]
            for i, (s, off, per) in enumerate(self._where)
            if per is None
        }
        buffer = function_buffer if self.keeps_buffers else ca.Function.buffer
        for fn, j0, count in self._calls():
            if count not in buffers:
                tiled = {i: np.tile(a, count) for i, a in shared.items()}
                buffers[count] = (*buffer(fn), tiled)
            buf, run, tiled = buffers[count]
            for i, (s, off, per) in enumerate(self._where):
                if per is None:
                    piece = tiled[i]
                else:
                    piece = src[s][off + j0 * per : off + (j0 + count) * per]
                buf.set_arg(i, memoryview(piece))
            if sink is not None and (j0 + count - c0) * n1 > chunk.size:
                sink(c0, j0, chunk[: (j0 - c0) * n1].reshape(j0 - c0, n1))
                c0 = j0
            for i, o in enumerate(out):
                n = f.nnz_out(i)
                if o is None:
                    o, at = chunk, j0 - c0
                else:
                    at = j0
                buf.set_res(i, memoryview(o[at * n : (at + count) * n]))
            run()
            if buf.ret() != 0:
                raise RuntimeError(f"{f.name()}: evaluation failed (return code {buf.ret()})")
        if sink is not None and self.nw > c0:
            sink(c0, self.nw, chunk[: (self.nw - c0) * n1].reshape(self.nw - c0, n1))
        return out

    def _x0_sigma(self, src: list) -> tuple:
        """The windows' measured starts and the noise levels: the data vector's first and
        last pieces (:func:`_data_shapes`), what the continuity defects take of it."""
        (_, x0, per), (_, sigma, _) = self._where[1], self._where[11]
        return src[3][x0 : x0 + per * self.nw], src[3][sigma:]

    def _calls(self):
        """``(function, first window, windows)`` of each evaluation."""
        m = (self.nw // THREADS) * THREADS if self.pair is not None else 0
        for j0 in range(0, m, THREADS):
            yield self.pair, j0, THREADS
        for j0 in range(m, self.nw):
            yield self.fn, j0, 1


class WindowResidual(_WindowCalls):
    """The residual of all windows (and on linked windows the continuity defects of every
    consecutive pair), from the window residual function run window by window
    (:class:`_WindowCalls`): what :func:`residual_function`'s CasADi Function gives, to
    the bit. ``evaluate(v, p_base, S, data)`` returns what
    :func:`~.buffers.evaluate` returns of that Function: ``[r]``, linked ``[r, c]``."""

    def __init__(self, win_r: ca.Function, nw: int, where: list, link: bool, defects=None):
        super().__init__(win_r, nw, where)
        self.link, self.defects = link, defects

    def evaluate(self, v, p_base, S, data) -> list:
        src = _sources(v, p_base, S, data)
        out = self._windows(src)
        if not self.link:
            return [out[0]]
        x0, sigma = self._x0_sigma(src)
        c = evaluate(self.defects, out[1], src[0], x0, sigma, keep=self.keeps_buffers)
        return [out[0], c[0]]


class WindowOutputs(_WindowCalls):
    """The outputs ``(ny, L n_windows)`` of all windows from the window output function run
    window by window (:class:`_WindowCalls`); ``evaluate`` as :class:`WindowResidual`'s."""

    def size_out(self, i: int) -> tuple:
        """The shape of output ``i`` (all windows side by side)."""
        return (self.fn.size1_out(i), self.fn.size2_out(i) * self.nw)

    def evaluate(self, v, p_base, S, data) -> list:
        return [self._windows(_sources(v, p_base, S, data))[0]]


class WindowJacobian(_WindowCalls):
    """The residual and its Jacobian in ``v = [theta; vec(delta)]`` from the windows' own
    blocks: the compiled window function runs on ``THREADS`` windows at a time, each call
    writing straight into its windows' slices of the result (:meth:`casadi.Function.buffer`),
    and NumPy places the blocks in the sparse matrix. On an hour of 50 Hz pieces the same
    in one CasADi map cost 0.6 GB for the map's output pattern and work vectors, and its
    assembly in CasADi's virtual machine 1 GB more.

    Attributes
    ----------
    shape : tuple of int
        ``(m nw, K + nd nw)``, the Jacobian's shape.
    """

    def __init__(self, win_rj: ca.Function, nw: int, K: int, shapes: list, defects=None):
        super().__init__(win_rj, nw, _where_of(win_rj.size1_in(0), K, shapes, nw))
        self.win_rj, self.K, self.defects = win_rj, K, defects
        block = win_rj.sparsity_out(1)
        m = block.size1()
        self._colind = np.asarray(block.colind(), dtype=np.int64)
        self.shape = (m * nw, K + (block.size2() - K) * nw)
        # the whole Jacobian's CSC index arrays are kept for the slot count of every fit
        # once an evaluation asks for them (the same arrays for each evaluation); a wider
        # Jacobian (the discrepancy screen's, one per round: 0.5 kB per row of an hour of 50
        # Hz three-axis samples) makes them per call. Not made before: the penalised fits
        # evaluate their used slots' part only (:meth:`_used_part`), and the structure
        # IPOPT's Hessian is made of (:meth:`pattern`) is made once per solver; kept from
        # the start, the arrays held 50 MB per Model on an hour of samples that no fit read.
        # Kept weakly (:class:`_KeptIndex`): the Jacobians made of them hold them; once the
        # last is let go they go too (25-29 MB each on that hour, one pair per Model and
        # slot count, held to the end of a search by Jacobians no longer in use)
        self._keep_index = K <= KEPT_INDEX_SLOTS
        self._index = None

    def index_arrays(self, theta=None, windows: bool = True) -> tuple:
        """``(indices, indptr)`` of the Jacobian's CSC matrix, or of its part of the
        parameter columns ``theta`` (sorted slots; default all) and, with ``windows``, every
        window's own columns (as :meth:`_part` lays them out)."""
        whole = theta is None and windows
        kept = None if not whole else _KeptIndex.get(getattr(self, "_index", None))
        if kept is not None:
            return kept
        block, nw, K = self.win_rj.sparsity_out(1), self.nw, self.K
        theta = np.arange(K) if theta is None else np.asarray(theta, dtype=int)
        m, col = block.size1(), self._colind
        row = np.asarray(block.row(), dtype=np.int64)
        counts = np.diff(col)
        spans = self.block_spans(theta, windows)
        total = sum(b - a for a, b in spans) * nw
        big = max(m * nw, total) >= np.iinfo(np.int32).max
        itype = np.int64 if big else np.int32
        off = (np.arange(nw, dtype=itype) * itype(m))[:, None]
        row = row.astype(itype)
        # theta columns: every window's rows in turn; then each window's own columns,
        # written in place (no 64-bit pieces and their concatenation: 20 bytes an entry)
        indices = np.empty(total, dtype=itype)
        at = 0
        for a, b in spans:
            piece = indices[at : at + (b - a) * nw].reshape(nw, b - a)
            np.add(row[a:b][None, :], off, out=piece)
            at += (b - a) * nw
        sizes = np.r_[counts[theta] * nw, np.tile(counts[K:], nw) if windows else []]
        return indices, np.r_[0, np.cumsum(sizes)].astype(itype)

    def block_spans(self, theta, windows: bool) -> list:
        """``(a, b)`` of each part's column group within a window block's nonzeros: each
        parameter column of ``theta``, then (``windows``) the window's own columns."""
        col, K = self._colind, self.K
        spans = [(int(col[c]), int(col[c + 1])) for c in theta]
        return spans + ([(int(col[K]), int(col[-1]))] if windows else [])

    def window_column_counts(self) -> np.ndarray:
        """The nonzeros of each of a window's own columns in its block (the columns after
        the ``K`` parameter slots)."""
        return np.diff(self._colind)[self.K :]

    def pattern(self) -> sp.csc_matrix:
        """The Jacobian's structure: a CSC matrix of ones."""
        indices, indptr = self.index_arrays()
        return sp.csc_matrix((np.ones(indices.size), indices, indptr), shape=self.shape)

    def defect_sparsity(self) -> ca.Sparsity:
        """The structure of the defects' Jacobian (linked windows)."""
        return self.defects.sparsity_out(1)

    def matrix(self, blocks: np.ndarray) -> sp.csc_matrix:
        """The Jacobian (CSC) from the nonzeros of the window blocks, window after window."""
        part = self._part(None, True)
        part.fill(np.asarray(blocks).reshape(self.nw, -1), 0)
        return part.matrix()

    def _part(self, theta, windows: bool) -> _Part:
        """An empty :class:`_Part` of the Jacobian (:meth:`index_arrays`)."""
        K = self.K
        th = np.arange(K) if theta is None else np.asarray(theta, dtype=int)
        indices, indptr = self.index_arrays(theta, windows)
        if theta is None and windows and self._keep_index:
            self._index = _KeptIndex(indices, indptr)
        n_cols = th.size + ((self.shape[1] - K) if windows else 0)
        spans = self.block_spans(th, windows)
        return _Part(spans, self.nw, indices, indptr, (self.shape[0], n_cols))

    def _used_part(self, used: int) -> _Part:
        """An empty :class:`_Part` of the whole Jacobian's shape whose parameter slots from
        ``used`` on have no entries (a fit's unused slots, fixed at zero); its index arrays
        kept for the last ``used`` asked (every iterate of a fit asks the same) while a
        matrix made of them is alive (:class:`_KeptIndex`)."""
        K = self.K
        kept = getattr(self, "_used_index", None)
        arrays = _KeptIndex.get(kept[1]) if kept is not None and kept[0] == used else None
        if arrays is None:
            self._used_index = None  # (the last let go before these are made)
            indices, ptr = self.index_arrays(np.arange(used), True)
            indptr = np.r_[ptr[: used + 1], np.full(K - used, ptr[used]), ptr[used + 1 :]]
            arrays = (indices, indptr.astype(ptr.dtype))
            self._used_index = (used, _KeptIndex(*arrays))
        spans = self.block_spans(np.arange(used), True)
        return _Part(spans, self.nw, *arrays, self.shape)

    def __call__(self, v, p_base, S, data, parts=None, used=None) -> tuple:
        """``(r, J)``, and on linked windows ``(r, J, c, Jc)`` (``J``, ``Jc`` scipy CSC).

        ``parts``: ``[(theta, windows), ...]``, each a part of ``J``'s columns (the
        parameter slots ``theta``, sorted, and with ``windows`` every window's own columns,
        in ``J``'s order); ``J`` is then the list of these parts, each the same numbers as
        that slice of ``J``, without ``J`` itself. A part ``("dense", theta, out, col0)``
        adds the parameter columns ``theta`` into the zeros of ``out[:, col0:]`` (its
        first rows: ``J``'s; the numbers of ``J[:, theta].toarray()``) and is None in
        the list; a part object (``fill``, ``matrix``: :class:`.penalty.StackedPart`) is
        filled as it is and its ``matrix()`` is in the list.

        ``used``: the parameter slots from ``used`` on left empty in ``J`` (no entries; a
        fit's unused slots, fixed at zero, whose columns no fit reads): on an hour of 50 Hz
        three-axis samples each slot's column is 13 MB per copy of ``J``.

        The window blocks are written into the matrices :data:`CHUNK_WINDOWS` windows at a
        time (not all windows' blocks, then the matrix: on an hour of 50 Hz samples a
        second copy of ``J``'s values while it was made)."""
        src = [np.ascontiguousarray(np.asarray(a, dtype=float).reshape(-1, order="F"))
               for a in (v, p_base, S, data)]  # fmt: skip
        part = self._used_part if used is not None and used < self.K else None
        made = (
            [part(int(used)) if part else self._part(None, True)]
            if parts is None
            else [
                p
                if hasattr(p, "fill")  # a part made by the caller (penalty.StackedPart)
                else _DensePart(self, *p[1:])
                if isinstance(p[0], str)
                else self._part(*p)
                for p in parts
            ]
        )

        def sink(j0, j1, blocks):
            for part in made:
                part.fill(blocks, j0)

        out = self._windows(src, sink)
        mats = [part.matrix() for part in made]
        J = mats[0] if parts is None else mats
        if self.defects is None:
            return out[0], J
        x0, sigma = self._x0_sigma(src)
        c, Jc = evaluate(self.defects, out[2], out[3], src[0], x0, sigma, keep=self.keeps_buffers)
        return out[0], J, c, csc_of(Jc, self.defects.sparsity_out(1))


class _KeptIndex:
    """A Jacobian's CSC ``(indices, indptr)`` held weakly: alive while a matrix made of them
    (:meth:`_Part.matrix` shares them) is; :meth:`get` gives them back, or None once let go."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray) -> None:
        self.refs = (weakref.ref(indices), weakref.ref(indptr))

    @staticmethod
    def get(kept) -> tuple | None:
        """``(indices, indptr)`` of ``kept`` (a :class:`_KeptIndex` or None) while alive."""
        if kept is None:
            return None
        arrays = tuple(r() for r in kept.refs)
        return None if any(a is None for a in arrays) else arrays


class _Part:
    """A part of a :class:`WindowJacobian`'s columns filled window block by block."""

    def __init__(self, spans, nw: int, indices, indptr, shape) -> None:
        self.spans, self.nw, self.shape = spans, nw, shape
        self.indices, self.indptr = indices, indptr
        self.data = np.empty(indices.size)
        # where each column group's entries start in ``data`` (window 0)
        sizes = [(b - a) * nw for a, b in spans]
        self.starts = np.r_[0, np.cumsum(sizes)[:-1]].astype(np.int64) if sizes else []

    def fill(self, blocks: np.ndarray, j0: int) -> None:
        """Windows ``j0 : j0 + len(blocks)`` from their blocks' nonzeros (one row each)."""
        j1 = j0 + blocks.shape[0]
        for (a, b), at in zip(self.spans, self.starts, strict=True):
            w = b - a
            self.data[at + j0 * w : at + j1 * w].reshape(j1 - j0, w)[...] = blocks[:, a:b]

    def matrix(self) -> sp.csc_matrix:
        """The filled part as a CSC matrix (sharing this part's arrays)."""
        return sp.csc_matrix((self.data, self.indices, self.indptr), shape=self.shape, copy=False)


class _DensePart:
    """Parameter columns of a :class:`WindowJacobian` added into a dense array's zeros
    window block by block (:meth:`WindowJacobian.__call__`)."""

    def __init__(self, fj: WindowJacobian, theta, out: np.ndarray, col0: int) -> None:
        block = fj.win_rj.sparsity_out(1)
        self.m = block.size1()
        self.row = np.asarray(block.row(), dtype=np.int64)
        self.spans = fj.block_spans(np.asarray(theta, dtype=int), False)
        self.out, self.col0 = out, int(col0)

    def fill(self, blocks: np.ndarray, j0: int) -> None:
        """Windows ``j0 : j0 + len(blocks)`` from their blocks' nonzeros (one row each)."""
        n = blocks.shape[0]
        off = (np.arange(j0, j0 + n, dtype=np.int64) * self.m)[:, None]
        for i, (a, b) in enumerate(self.spans):
            rows = (self.row[a:b][None, :] + off).ravel()
            self.out[rows, self.col0 + i] += blocks[:, a:b].ravel()

    def matrix(self) -> None:
        """Nothing: the columns are in the caller's array."""
        return None


#: Windows whose Jacobian blocks are held at once while a Jacobian is made
#: (:meth:`WindowJacobian.__call__`): on an hour of 50 Hz three-axis pieces about 0.7 MB
#: per window and parameter slot.
CHUNK_WINDOWS = 16

#: Parameter slots up to which a :class:`WindowJacobian` keeps its CSC index arrays:
#: ``functions.THETA_SLOTS`` (which imports this module), the slots of every fit.
KEPT_INDEX_SLOTS = 6

#: Threads evaluating the windows side by side.
THREADS = 2

#: Windows from which the window functions' buffers (their work vectors) are made for each
#: evaluation of all windows and let go with it, not kept with the cached function
#: (:class:`_WindowCalls`): made once for the ``nw / THREADS`` runs of an evaluation. On an
#: hour of 50 Hz three-axis pieces (360) the Jacobian's is 14 MB, made in 0.2 ms against
#: 3 s for the evaluation, and the defects' 5 MB; kept, one of each per Model and slot
#: count stayed resident through the whole search. Few windows (a short log's fits, many
#: cheap evaluations) keep theirs.
KEPT_BUFFER_WINDOWS = 64


def map_windows(fn: ca.Function, nw: int, args: list) -> list:
    """``fn`` over ``nw`` windows (``args`` as :meth:`casadi.Function.map` takes them: a
    window's inputs side by side, or one for all), ``THREADS`` windows at a time.

    CasADi's threaded map keeps a work vector per window it maps, not per thread: for the
    Jacobian of an hour of 50 Hz pieces, 570 MB. A serial map of threaded maps of
    ``THREADS`` windows keeps ``THREADS`` (the remaining windows are one more call)."""
    if nw < 2 * THREADS:
        return fn.map(nw, "thread", THREADS).call(args)
    per = [fn.size2_in(i) for i in range(fn.n_in())]
    m = (nw // THREADS) * THREADS
    mapped = fn.map(THREADS, "thread", THREADS).map(m // THREADS, "serial")

    def part(a, w, lo, hi):
        whole = (lo, hi) == (0, nw)
        return a[:, lo * w : hi * w] if a.shape[1] == w * nw != w and not whole else a

    out = mapped.call([part(a, w, 0, m) for a, w in zip(args, per, strict=True)])
    if m == nw:
        return out
    rest = fn.map(nw - m, "thread", THREADS).call(
        [part(a, w, m, nw) for a, w in zip(args, per, strict=True)]
    )
    return [ca.horzcat(a, b) for a, b in zip(out, rest, strict=True)]


def _build_problem(model, L, nw, K, outputs, substeps, jit, link=False):
    """``fr, fj, fy`` of all windows, run window by window from NumPy
    (:class:`_WindowCalls`): ``fr`` the :class:`WindowResidual` (with ``link`` the
    continuity defects of every consecutive pair of windows too), ``fj`` the
    :class:`WindowJacobian` (the same and their Jacobians in ``v = [theta; vec(delta)]``,
    NumPy and scipy CSC), ``fy`` the :class:`WindowOutputs`; each takes ``(v, p_base, S,
    data)``. :func:`residual_function` is ``fr`` as one CasADi Function."""
    win_r, win_rj, win_y = _window_functions(model, L, K, outputs, substeps, jit, link)
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    shapes = _data_shapes(model, L, nw, n_rate + n_ws, link, sigma_size(model, outputs))
    where = _where_of(nd, K, shapes, nw)
    defects = defects_j = None
    if link:
        defects, defects_j = _defect_functions(model, K, outputs, nd, nw, shapes, win_rj)
    fr = WindowResidual(win_r, nw, where, link, defects)
    # the outputs' function takes (delta, x0, U, dt, p_base, S, theta): those inputs' places
    fy = WindowOutputs(win_y, nw, [where[i] for i in (0, 1, 2, 3, 8, 9, 10)])
    return fr, WindowJacobian(win_rj, nw, K, shapes, defects_j), fy


def _defect_functions(model, K, outputs, nd, nw, shapes, win_rj) -> tuple:
    """The continuity defects of every consecutive pair of ``nw`` linked windows, from the
    windows' end states: ``(x_end, v, x0, sigma) -> c`` and ``(x_end, dx_end, v, x0,
    sigma) -> (c, dc/dv)`` (``x0`` the windows' measured starts, ``sigma`` the noise
    levels: the data vector's first and last pieces, :func:`_data_shapes`)."""
    (nx0, _), (n_sigma, _) = shapes[0], shapes[-1]
    v = ca.MX.sym("v", K + nd * nw)
    X0 = ca.MX.sym("x0", nx0, nw)
    SIG = ca.MX.sym("sigma", n_sigma, 1)
    D = ca.reshape(v[K:], nd, nw)
    XE = ca.MX.sym("x_end", model.nx, nw)
    DX = ca.MX.sym("dx_end", ca.repmat(win_rj.sparsity_out(3), 1, nw))
    if nw == 1:  # one window: nothing to join
        return (
            ca.Function("defects_r", [XE, v, X0, SIG], [ca.MX(0, 1)]),
            ca.Function("defects", [XE, DX, v, X0, SIG], [ca.MX(0, 1), ca.MX(0, v.shape[0])]),
        )
    lf = _link_function(model, K, outputs).map(nw - 1)
    sig = ca.repmat(SIG, 1, nw - 1)
    C = ca.vec(lf(XE[:, :-1], ca.DM.zeros(model.nx, (K + nd) * (nw - 1)), D[:, 1:],
                  X0[:, 1:], sig)[0])  # fmt: skip
    Cj, A, B = lf(XE[:, :-1], DX[:, : (K + nd) * (nw - 1)], D[:, 1:], X0[:, 1:], sig)
    m = nd * (nw - 1)
    a_blocks = [A[:, j * (K + nd) : (j + 1) * (K + nd)] for j in range(nw - 1)]
    b_blocks = [B[:, j * nd : (j + 1) * nd] for j in range(nw - 1)]
    JC_th = ca.vertcat(*[blk[:, :K] for blk in a_blocks]) if K else ca.MX(m, 0)
    JC_d = ca.horzcat(ca.diagcat(*[blk[:, K:] for blk in a_blocks]), ca.MX(m, nd))
    JC_d = JC_d + ca.horzcat(ca.MX(m, nd), ca.diagcat(*b_blocks))
    JC = ca.horzcat(JC_th, JC_d)
    return (
        ca.Function("defects_r", [XE, v, X0, SIG], [C]),
        ca.Function("defects", [XE, DX, v, X0, SIG], [ca.vec(Cj), JC]),
    )


def _residual_graph(model, L, nw, K, outputs, substeps, jit, link=False) -> ca.Function:
    """:class:`WindowResidual` as one CasADi Function of all windows (an expression CasADi
    can differentiate in every input, :func:`residual_function`): the windows mapped
    ``THREADS`` at a time (:func:`map_windows`)."""
    win_r = _window_functions(model, L, K, outputs, substeps, jit, link)[0]
    n_att, n_rate, n_ws, n_lag = delta_layout(model, outputs)
    nd = n_att + n_rate + n_ws + n_lag
    v = ca.MX.sym("v", K + nd * nw)
    pb = ca.MX.sym("p_base", model.n_p)
    S = ca.MX.sym("S", model.n_p, K)
    shapes = _data_shapes(model, L, nw, n_rate + n_ws, link, sigma_size(model, outputs))
    data = ca.MX.sym("data", sum(a * b for a, b in shapes))
    pieces, i = [], 0
    for a, b in shapes:
        pieces.append(ca.reshape(data[i : i + a * b], a, b))
        i += a * b
    th, D = v[:K], ca.reshape(v[K:], nd, nw)
    args = [D, *pieces[:7], pb, S, th, pieces[-1], *(pieces[7:8] if link else [])]
    out_r = map_windows(win_r, nw, args)
    R = out_r[0]
    if not link:
        return ca.Function("r", [v, pb, S, data], [ca.vec(R)])
    if nw == 1:  # one window: nothing to join
        return ca.Function("r", [v, pb, S, data], [ca.vec(R), ca.MX(0, 1)])
    lf = _link_function(model, K, outputs).map(nw - 1)
    sig = ca.repmat(pieces[-1], 1, nw - 1)
    C = ca.vec(lf(out_r[1][:, :-1], ca.DM.zeros(model.nx, (K + nd) * (nw - 1)),
                  D[:, 1:], pieces[0][:, 1:], sig)[0])  # fmt: skip
    return ca.Function("r", [v, pb, S, data], [ca.vec(R), C])
