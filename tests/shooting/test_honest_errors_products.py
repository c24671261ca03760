"""The honest errors', the lag score's and the screen's products without copies of the
Jacobian (:func:`airbearing.analysis.shooting.one_trajectory._kkt_solve`, ``_influence``,
``_weighted_rows``; :func:`airbearing.analysis.discrepancy.lag_score._nonempty_columns`;
``linearisation._column_square_sums`` and ``_transposed_product``): the same numbers to the bit
as scipy's products on the copies they replace (the rows of the measurements, the weighted
rows, the column-scaled matrix, the non-empty columns, the squared entries, the row-major
copy of dense columns).

The reference is the bordered (KKT) solve as it was written with those copies:
``F = Jm' Jm`` of ``Jm = J[:n]`` (or of ``diag(w) Jm``), ``M = ((Jm Dc) X)' / c``.
Entries span 14 decades, so a sum taken in another order would differ in its last bits.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.discrepancy.lag_score import _nonempty_columns
from airbearing.analysis.shooting.one_trajectory import _influence, _kkt, _kkt_solve, _weighted_rows


def _jacobian(rng, nw=25, n=60, nd=6, k=3, n_defect=40):
    A = rng.standard_normal((nw * n + n_defect, k)) * 10.0 ** rng.uniform(-7, 7, size=k)
    A[rng.random(A.shape) < 0.05] = 0.0
    blocks = [sp.csc_matrix(rng.standard_normal((n, nd)) * 10.0 ** rng.uniform(-3, 3, nd))
              for _ in range(nw)]  # fmt: skip
    D = sp.vstack([sp.block_diag(blocks), sp.random(n_defect, nw * nd, density=0.05,
                                                    random_state=rng)]).tocsc()  # fmt: skip
    J = sp.hstack([sp.csc_matrix(A), D]).tocsc()
    J.data[rng.random(J.nnz) < 0.01] = 0.0  # explicit zeros, as a compiled pattern has
    # continuity: each pair's states joined (full row rank, as the defects' Jacobian is)
    m = (nw - 1) * nd
    rows = np.r_[np.arange(m), np.arange(m)]
    cols = k + np.r_[np.arange(m), nd + np.arange(m)]
    vals = np.r_[rng.uniform(0.5, 2.0, m), -np.ones(m)]
    C = sp.csr_matrix((vals, (rows, cols)), shape=(m, J.shape[1]))
    return J, C, nw * n, k


def _reference(Jm, C, k, level=None):
    """The bordered solve with scipy's copies (the code these helpers replace)."""
    if level is not None:
        Jm = sp.csc_matrix(sp.diags(1.0 / np.sqrt(level)) @ Jm)
    F = sp.csc_matrix(Jm.T @ Jm)
    c = np.sqrt(np.maximum(F.diagonal(), 0.0))
    c = np.where(c > 0, c, 1.0)
    Dc = sp.diags(1.0 / c)
    Kkt = sp.bmat([[Dc @ F @ Dc, (C @ Dc).T], [C @ Dc, None]], format="csc")
    rhs = np.zeros((Kkt.shape[0], k))
    rhs[np.arange(k), np.arange(k)] = 1.0
    X = splu(Kkt).solve(rhs)
    cov0 = X[:k] / np.outer(c[:k], c[:k])
    M = ((Jm @ Dc) @ X[: Jm.shape[1]]).T / c[:k, None]
    return 0.5 * (cov0 + cov0.T), M


@pytest.mark.parametrize("seed", range(4))
def test_the_bordered_solve_on_the_measurement_rows_is_scipys(seed):
    rng = np.random.default_rng(seed)
    J, C, n, k = _jacobian(rng)
    cov_ref, M_ref = _reference(J[:n], C, k)
    sol = _kkt_solve(J, C, n, k)  # J's defect rows below n: no copy of the first n
    np.testing.assert_array_equal(sol[0], cov_ref)
    M = _influence(J, n, sol, k)
    np.testing.assert_array_equal(M, M_ref)
    assert M.shape == (k, n) and M.flags.f_contiguous == M_ref.flags.f_contiguous
    cov, M2 = _kkt(J[:n], C, k)
    np.testing.assert_array_equal(cov, cov_ref)
    np.testing.assert_array_equal(M2, M_ref)


@pytest.mark.parametrize("seed", range(4))
def test_the_weighted_bordered_solve_is_scipys(seed):
    rng = np.random.default_rng(seed)
    J, C, n, k = _jacobian(rng)
    level = rng.uniform(0.1, 1.0, n)
    cov_ref, M_ref = _reference(J[:n], C, k, level)
    np.testing.assert_array_equal(_kkt_solve(J, C, n, k, level)[0], cov_ref)
    cov, M = _kkt(J[:n], C, k, level)
    np.testing.assert_array_equal(cov, cov_ref)
    np.testing.assert_array_equal(M, M_ref)


def test_the_weighted_rows_are_scipys_product():
    rng = np.random.default_rng(7)
    J, _, n, _ = _jacobian(rng)
    # empty columns (first, inside, last) and a column of the defect rows only
    E = sp.csc_matrix((J.shape[0], 1))
    D = sp.csc_matrix(([1.0], ([J.shape[0] - 1], [0])), shape=(J.shape[0], 1))
    J = sp.hstack([E, J[:, :5], E, D, J[:, 5:], E]).tocsc()
    w = rng.uniform(0.5, 3.0, n)
    w[:5] = 0.0  # rows weighted to zero: their entries left out, as scipy leaves them
    ref = sp.csc_matrix(sp.diags(w) @ J[:n])
    got = _weighted_rows(J, n, w)
    assert got.has_sorted_indices
    for a in ("indptr", "indices", "data"):
        np.testing.assert_array_equal(getattr(got, a), getattr(ref, a))


def test_the_non_empty_columns_share_the_jacobians_entries():
    rng = np.random.default_rng(3)
    J, _, _, _ = _jacobian(rng)
    J = sp.hstack([J[:, :4], sp.csc_matrix((J.shape[0], 2)), J[:, 4:]]).tocsc()  # held states
    cols = np.flatnonzero(np.diff(J.indptr) > 0)
    assert cols.size < J.shape[1]
    got, ref = _nonempty_columns(J, cols), J[:, cols]
    assert np.shares_memory(got.data, J.data)
    keep = rng.random(J.shape[0]) < 0.8  # (the lag score takes rows of it)
    for g, r in ((got, ref), (sp.csc_matrix(got[keep]), sp.csc_matrix(ref[keep]))):
        for a in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(g, a), getattr(r, a))


def test_the_screens_column_norms_are_scipys():
    from airbearing.analysis.discrepancy.linearisation import _column_square_sums

    rng = np.random.default_rng(5)
    J, _, _, _ = _jacobian(rng)
    J = sp.hstack([J, sp.csc_matrix((J.shape[0], 3))]).tocsc()  # empty columns: 0
    ref = np.asarray(J.power(2).sum(axis=0)).ravel()
    np.testing.assert_array_equal(_column_square_sums(J), ref)
    np.testing.assert_array_equal(_column_square_sums(J, blocks=7), ref)


def test_the_screens_product_with_column_major_columns_is_scipys():
    from airbearing.analysis.discrepancy.linearisation import _transposed_product

    rng = np.random.default_rng(11)
    J, _, _, _ = _jacobian(rng)
    A = np.asfortranarray(rng.standard_normal((J.shape[0], 7)) * 10.0 ** rng.uniform(-7, 7, 7))
    ref = np.asarray(J.T @ A)
    got = _transposed_product(J, A)
    np.testing.assert_array_equal(got, ref)
    assert got.flags.c_contiguous == ref.flags.c_contiguous
