"""CasADi sparse matrices as scipy CSC, and the CSC operations of the fits: a pattern
converted once (:func:`to_csc`, :func:`csc_of`), columns scaled in place
(:func:`scale_columns`), a small block stacked below (:func:`vstack_csc`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
from collections import OrderedDict

import casadi as ca
import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.function_cache import CACHE_SIZE

_PATTERNS: OrderedDict = OrderedDict()


def _pattern_of(spy: ca.Sparsity) -> tuple:
    """``(row, colind)`` of a CasADi sparsity as int64 arrays, converted once per pattern."""
    key = (spy.hash(), spy.size1(), spy.size2(), spy.nnz())
    pat = _PATTERNS.get(key)
    if pat is None:
        pat = (np.asarray(spy.row(), dtype=np.int64), np.asarray(spy.colind(), dtype=np.int64))
        _PATTERNS[key] = pat
        while len(_PATTERNS) > CACHE_SIZE:
            _PATTERNS.popitem(last=False)
    return pat


def to_csc(J: ca.DM) -> sp.csc_matrix:
    """A CasADi sparse matrix as scipy CSC, its (constant) pattern converted once."""
    return csc_of(np.asarray(J.nonzeros(), dtype=float), J.sparsity())


def csc_of(nz: np.ndarray, spy: ca.Sparsity) -> sp.csc_matrix:
    """The nonzeros ``nz`` (CasADi's column-major order) of a matrix of sparsity ``spy`` as
    scipy CSC, sharing ``nz`` (no copy)."""
    row, colind = _pattern_of(spy)
    return sp.csc_matrix((nz, row, colind), shape=(spy.size1(), spy.size2()), copy=False)


#: Most entries of ``J`` scaled at once by :func:`scale_columns` (its factors repeated for
#: that many entries: 8 MB, where the whole matrix's were 100 MB on an hour of samples).
SCALE_BLOCK_ENTRIES = 1 << 20


def scale_columns(J: sp.csc_matrix, scale: np.ndarray) -> sp.csc_matrix:
    """``J @ diag(scale)`` for a CSC ``J``, in place (each column times its factor: the
    same numbers as the product, without a copy of ``J``), block of columns by block of
    at most about :data:`SCALE_BLOCK_ENTRIES` entries (one wider column is one block)."""
    scale = np.asarray(scale, dtype=float)
    ptr = J.indptr
    counts = np.diff(ptr)
    n = counts.size
    a = 0
    while a < n:
        # the columns whose entries end within the block's budget (at least one column)
        b = int(np.searchsorted(ptr, ptr[a] + SCALE_BLOCK_ENTRIES, side="right")) - 1
        b = min(max(b, a + 1), n)
        J.data[ptr[a] : ptr[b]] *= np.repeat(scale[a:b], counts[a:b])
        a = b
    return J


def _stacking(A, B, what: str) -> tuple[sp.csc_matrix, sp.csc_matrix, np.ndarray]:
    """``A`` and ``B`` as CSC with sorted indices, and where each of ``B``'s entries goes
    in ``A``'s arrays when ``B`` is stacked below ``A`` (after its column's entries)."""
    A, B = sp.csc_matrix(A), sp.csc_matrix(B)
    if A.shape[1] != B.shape[1]:  # pragma: no cover - programming error
        raise ValueError(f"{what}: the matrices have different numbers of columns")
    A.sort_indices()
    B.sort_indices()
    col = np.repeat(np.arange(B.shape[1]), np.diff(B.indptr))
    return A, B, A.indptr[col + 1]


def vstack_csc(A: sp.csc_matrix, B: sp.csc_matrix, consume: bool = False) -> sp.csc_matrix:
    """``[A; B]`` as CSC for a small ``B`` (each column: ``A``'s entries, then ``B``'s): the
    entries of ``B`` inserted into ``A``'s arrays, without scipy's detour through COO and a
    sort of every entry (a few hundred MB and most of a second on an hour of samples).

    ``consume``: ``A`` (CSC) is the caller's to give up: its arrays are let go as the
    stacked ones are made (:func:`let_go`; its values before the indices are copied, on an
    hour of samples 50 MB less at once), and ``A`` is not to be used again.
    """
    given = A
    A, B, at = _stacking(A, B, "vstack_csc")
    shape = (A.shape[0] + B.shape[0], A.shape[1])
    # where B's entries go in the stacked arrays (np.insert's places: before A's entry
    # ``at``, in B's order), one mask for both arrays
    places = at + np.arange(B.nnz, dtype=at.dtype)
    rest = np.ones(A.nnz + B.nnz, dtype=bool)
    rest[places] = False
    data = np.empty(rest.size, dtype=A.data.dtype)
    data[places] = B.data
    data[rest] = A.data
    # 32-bit indices while they fit (as A's): 64-bit ones held a third more of a long log's
    # Jacobian, and their copy of A's indices as much again while it was stacked
    big = max(shape[0], rest.size) >= np.iinfo(np.int32).max
    itype = np.int64 if big else np.int32
    indptr = A.indptr.astype(itype) + B.indptr.astype(itype)
    if consume:
        let_go(given, A, values_only=True)
    indices = np.empty(rest.size, dtype=itype)
    indices[places] = B.indices.astype(itype) + itype(A.shape[0])
    indices[rest] = A.indices
    if consume:
        let_go(given, A)
    return sp.csc_matrix((data, indices, indptr), shape=shape, copy=False)


def let_go(*mats, values_only: bool = False) -> None:
    """Drop sparse matrices' references to their arrays (their values only, with
    ``values_only``), so the arrays are freed where nothing else holds them (a matrix no
    one will read again, whose holders, a tuple of results say, outlive its use)."""
    for M in mats:
        M.data = None
        if not values_only:
            M.indices = M.indptr = None


def stacked_column_norms(A: sp.csc_matrix, B: sp.csc_matrix) -> np.ndarray:
    """The 2-norm of each column of ``[A; B]`` (:func:`vstack_csc`) for a small ``B``:
    the same numbers as ``sqrt(vstack_csc(A, B).power(2).sum(axis=0))`` (scipy's sums:
    each column's squares in its stored order, ``np.add.reduceat``), without the stacked
    matrix and its square, only the stacked entries squared (on an hour of samples the
    two held some 300 MB at every fit's start, beside the Jacobian itself)."""
    A, B, at = _stacking(A, B, "stacked_column_norms")
    squares = np.insert(A.data, at, B.data)
    np.square(squares, out=squares)
    indptr = A.indptr.astype(np.intp) + B.indptr.astype(np.intp)
    sums = np.zeros(A.shape[1])
    filled = np.flatnonzero(np.diff(indptr))
    if filled.size:
        sums[filled] = np.add.reduceat(squares, indptr[filled])
    return np.sqrt(sums)


#: Fewest column blocks in which the Gram matrices below are formed ...
GRAM_BLOCKS = 4
#: ... and most entries of a block (more blocks for a larger matrix): a block and its CSR
#: copy, some 12 MB, are what a Gram matrix holds beyond its factors ...
GRAM_BLOCK_ENTRIES = 1 << 19
#: ... up to this many blocks (larger ones beyond: a block's product passes over every
#: entry of the other factor, so a number of blocks growing with the log made the Gram
#: matrix quadratic in it: 2000 pieces of 5.5 h of 50 Hz dof-3 samples, 104 blocks, 7.8 s
#: of CPU against 0.44 s for the hour's 360 pieces in 19 blocks).
GRAM_MAX_BLOCKS = 16


def _column_blocks(J: sp.csc_matrix) -> np.ndarray:
    """Edges of blocks of columns of about equal numbers of entries (at least
    :data:`GRAM_BLOCKS`, at most :data:`GRAM_BLOCK_ENTRIES` entries each where columns
    allow, at most :data:`GRAM_MAX_BLOCKS` blocks)."""
    n = J.shape[1]
    m = max(GRAM_BLOCKS, min(GRAM_MAX_BLOCKS, -(-J.nnz // GRAM_BLOCK_ENTRIES)))
    cuts = np.searchsorted(J.indptr, np.linspace(0, J.nnz, m + 1)[1:-1])
    return np.unique(np.r_[0, np.clip(cuts, 1, max(n - 1, 1)), n])


def gram(J) -> sp.csc_matrix:
    """``J^T J`` of a sparse ``J`` (:func:`cross_gram`): the same matrix to the bit as
    scipy's ``J.T @ J``, in blocks of at most :data:`GRAM_BLOCK_ENTRIES` entries."""
    return cross_gram(J, J)


def cross_gram(X, Y, stop: int | None = None) -> sp.csc_matrix:
    """``X[:stop]^T Y[:stop]`` for CSC ``X`` and ``Y`` of the same rows, made block of
    columns of ``Y`` by block (a copy of one block at a time, not of ``Y`` whole, nor of
    the first ``stop`` rows of either).

    Every entry is scipy's sum of ``X.T @ Y``, in its order: entry ``(i, j)`` accumulates
    over the stored entries of column ``i`` of ``X`` in turn (a row from ``stop`` on takes
    part in no sum: its partner in ``Y``'s block is empty). The result's row indices are
    sorted in each column.
    """
    X, Y = sp.csc_matrix(X), sp.csc_matrix(Y)
    rows = Y.shape[0] if stop is None else min(stop, Y.shape[0])
    Xt = X.T
    parts = []
    edges = _column_blocks(Y)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        B = Y[:rows, a:b] if rows < Y.shape[0] else Y[:, a:b]
        B = sp.csc_matrix((B.data, B.indices, B.indptr), shape=(X.shape[0], b - a))
        parts.append(sp.csc_matrix(Xt @ B))
    return parts[0] if len(parts) == 1 else sp.hstack(parts, format="csc")


def gram_rows(J, stop: int) -> sp.csc_matrix:
    """``J[:stop]^T J[:stop]`` of a CSC ``J`` without a copy of its rows (:func:`cross_gram`):
    scipy's sums of ``J[:stop].T @ J[:stop]`` in their order."""
    return cross_gram(J, J, stop)


def add_row_products(G: sp.csc_matrix, R) -> sp.csc_matrix:
    """``G + R^T R`` with each entry's sum carried on from ``G``'s value over the rows of
    ``R`` in turn: scipy's Gram matrix of ``[A; R]`` to the bit when ``G`` is ``A``'s
    (its entries sum the rows of ``A``, then those of ``R`` in order, each product
    ``R[d, i] R[d, j]``; sums exactly 0 left out as scipy does). For a small ``R``: the
    rows a fit's intensity changes, added to the Gram matrix of those it does not."""
    G = sp.csc_matrix(G)
    G.sort_indices()
    R = sp.csr_matrix(R)
    nr, nc = G.shape
    per = np.diff(R.indptr)
    pairs = per.astype(np.int64) ** 2
    start = np.repeat(R.indptr[:-1].astype(np.int64), pairs)  # each pair's row start
    size = np.repeat(per.astype(np.int64), pairs)
    local = np.arange(int(pairs.sum()), dtype=np.int64) - np.repeat(np.cumsum(pairs) - pairs, pairs)
    p = start + local // np.maximum(size, 1)
    q = start + local % np.maximum(size, 1)
    new_keys = R.indices[q].astype(np.int64) * nr + R.indices[p]
    col = np.repeat(np.arange(nc, dtype=np.int64), np.diff(G.indptr))
    old_keys = col * nr + G.indices
    keys = np.union1d(old_keys, new_keys)
    data = np.zeros(keys.size)
    data[np.searchsorted(keys, old_keys)] = G.data
    np.add.at(data, np.searchsorted(keys, new_keys), R.data[p] * R.data[q])  # rows in turn
    kept = data != 0
    keys, data = keys[kept], data[kept]
    indptr = np.r_[0, np.cumsum(np.bincount(keys // nr, minlength=nc))]
    return sp.csc_matrix((data, keys % nr, indptr), shape=(nr, nc))


def column_abs_sums(J) -> np.ndarray:
    """``abs(J).sum(axis=0)`` of a CSC ``J`` (the same sums), block of columns by block:
    no copy of ``J``'s values."""
    J = sp.csc_matrix(J)
    edges = _column_blocks(J)
    return np.concatenate(
        [
            np.asarray(abs(J[:, a:b]).sum(axis=0)).ravel()
            for a, b in zip(edges[:-1], edges[1:], strict=True)
        ]
    )


_LIBC: object = None


def release_free_memory() -> None:
    """Give the free pages of the C heap back to the system (glibc's ``malloc_trim``; a
    no-op where there is none).

    glibc keeps what a phase frees for the next allocations; after the fits of an hour of
    samples that was some 70 MB of free pages in the middle of the heap, resident all
    through the process-noise estimate that followed (its peak is the process's).
    """
    global _LIBC
    if _LIBC is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _LIBC = libc.malloc_trim
            _LIBC.argtypes, _LIBC.restype = [ctypes.c_size_t], ctypes.c_int
        except (OSError, AttributeError):  # not glibc: the allocator's own policy
            _LIBC = False
    if _LIBC:
        _LIBC(0)


def trailing_columns(J: sp.csc_matrix, k: int) -> sp.csc_matrix:
    """``J[:, k:]`` sharing ``J``'s arrays (a CSC matrix's trailing columns are one
    contiguous run of its entries): the same matrix as the slice, without its copy (on an
    hour of 50 Hz three-axis samples about the size of ``J``, some 120 MB)."""
    ptr = J.indptr
    lo, hi = ptr[k], ptr[-1]
    return sp.csc_matrix(
        (J.data[lo:hi], J.indices[lo:hi], ptr[k:] - lo),
        shape=(J.shape[0], J.shape[1] - k),
        copy=False,
    )
