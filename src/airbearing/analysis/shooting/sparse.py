"""CasADi sparse matrices as scipy CSC, and the CSC operations of the fits: a pattern
converted once (:func:`to_csc`, :func:`csc_of`), columns scaled in place
(:func:`scale_columns`), a small block stacked below (:func:`vstack_csc`).
"""

from __future__ import annotations

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


def scale_columns(J: sp.csc_matrix, scale: np.ndarray) -> sp.csc_matrix:
    """``J @ diag(scale)`` for a CSC ``J``, in place (each column times its factor: the
    same numbers as the product, without a copy of ``J``)."""
    J.data *= np.repeat(np.asarray(scale, dtype=float), np.diff(J.indptr))
    return J


def vstack_csc(A: sp.csc_matrix, B: sp.csc_matrix) -> sp.csc_matrix:
    """``[A; B]`` as CSC for a small ``B`` (each column: ``A``'s entries, then ``B``'s): the
    entries of ``B`` inserted into ``A``'s arrays, without scipy's detour through COO and a
    sort of every entry (a few hundred MB and most of a second on an hour of samples)."""
    A, B = sp.csc_matrix(A), sp.csc_matrix(B)
    if A.shape[1] != B.shape[1]:  # pragma: no cover - programming error
        raise ValueError("vstack_csc: the matrices have different numbers of columns")
    A.sort_indices()
    B.sort_indices()
    col = np.repeat(np.arange(B.shape[1]), np.diff(B.indptr))
    at = A.indptr[col + 1]
    data = np.insert(A.data, at, B.data)
    # 32-bit indices while they fit (as A's): 64-bit ones held a third more of a long log's
    # Jacobian, and their copy of A's indices as much again while it was stacked
    big = max(A.shape[0] + B.shape[0], A.nnz + B.nnz) >= np.iinfo(np.int32).max
    itype = np.int64 if big else np.int32
    indices = np.insert(
        A.indices.astype(itype, copy=False), at, B.indices.astype(itype) + itype(A.shape[0])
    )
    return sp.csc_matrix(
        (data, indices, A.indptr.astype(itype) + B.indptr.astype(itype)),
        shape=(A.shape[0] + B.shape[0], A.shape[1]),
    )
