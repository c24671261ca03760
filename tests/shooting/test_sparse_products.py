"""The row-free products of the process-noise linearisation and the measurement-noise
estimate (:mod:`airbearing.analysis.shooting.sparse`): the same numbers to the bit as
scipy's products of the stacked or row-selected matrices they replace.

The matrices have the shape of a shooting fit's Jacobian (a few dense parameter columns,
then every window's own block of initial-state columns, a few defect rows below), with
entries over 14 decades, so that a sum taken in another order would differ in its last
bits. The reference is scipy's own product of the matrix the helper avoids making.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting import sparse as sps


def _jacobian(rng, nw=30, n=100, nd=6, k=2, n_defect=None):
    A = rng.standard_normal((nw * n, k)) * 10.0 ** rng.uniform(-7, 7, size=k)
    A[rng.random(A.shape) < 0.05] = 0.0
    blocks = [sp.csc_matrix(rng.standard_normal((n, nd)) * 10.0 ** rng.uniform(-3, 3, nd))
              for _ in range(nw)]  # fmt: skip
    Jm = sp.hstack([sp.csc_matrix(A), sp.block_diag(blocks, format="csc")]).tocsc()
    # defect rows: each links the last state of a window to the first of the next
    m = n_defect or (nw - 1) * nd
    C = sp.random(m, Jm.shape[1], density=0.02, random_state=rng, format="csc")
    C.data = rng.standard_normal(C.nnz) * 10.0 ** rng.uniform(-4, 4, C.nnz)
    return Jm, C


def _same(got, ref) -> None:
    got, ref = sp.csc_matrix(got), sp.csc_matrix(ref)
    got.sort_indices()
    ref.sort_indices()
    np.testing.assert_array_equal(got.indptr, ref.indptr)
    np.testing.assert_array_equal(got.indices, ref.indices)
    np.testing.assert_array_equal(got.data, ref.data)


def test_gram_of_the_first_rows_and_of_rows_added_below_is_scipys():
    rng = np.random.default_rng(0)
    for _ in range(3):
        Jm, C = _jacobian(rng)
        W = sp.random(C.shape[0], C.shape[0], density=0.05, random_state=rng, format="csr")
        J = sp.vstack([Jm, C], format="csc")  # a fit's Jacobian: measurement rows on top
        n = Jm.shape[0]
        _same(sps.gram_rows(J, n), Jm.T @ Jm)
        WC = (W + sp.eye(W.shape[0])) @ C
        A = sp.vstack([Jm, WC], format="csc")  # what the linearisation no longer makes
        _same(sps.add_row_products(sps.gram_rows(J, n), WC), A.T @ A)


def test_gram_and_cross_gram_of_selected_rows_are_scipys():
    rng = np.random.default_rng(1)
    sps_blocks = sps.GRAM_BLOCK_ENTRIES
    try:
        sps.GRAM_BLOCK_ENTRIES = 500  # many blocks
        Jm, _ = _jacobian(rng)
        rows = rng.permutation(Jm.shape[0])[: Jm.shape[0] // 2]
        prev = np.maximum(rows - 1, 0)
        csr = sp.csr_matrix(Jm)
        A, B = csr[rows], csr[prev]  # the rows as the estimate took them before
        Ac, Bc = sp.csc_matrix(Jm[rows]), sp.csc_matrix(Jm[prev])
        Ac.sort_indices()
        Bc.sort_indices()
        assert sps._column_blocks(Ac).size > sps.GRAM_BLOCKS + 1
        # never more than GRAM_MAX_BLOCKS (a block's product passes over all of the other
        # factor: more blocks on longer logs made the Gram matrix quadratic in them)
        assert sps._column_blocks(Ac).size - 1 <= sps.GRAM_MAX_BLOCKS
        assert -(-Ac.nnz // sps.GRAM_BLOCK_ENTRIES) > sps.GRAM_MAX_BLOCKS  # (the cap acts)
        _same(sps.gram(Ac), A.T @ A)
        AB = A.T @ B
        BA = sps.cross_gram(Bc, Ac)
        _same(BA.T + BA, AB + AB.T)
        a = rng.standard_normal(rows.size)
        np.testing.assert_array_equal(Ac.T @ a, A.T @ a)
    finally:
        sps.GRAM_BLOCK_ENTRIES = sps_blocks


def test_column_abs_sums_are_scipys():
    rng = np.random.default_rng(2)
    Jm, C = _jacobian(rng)
    J = sp.vstack([Jm, C], format="csc")
    J.data[J.indptr[5] : J.indptr[6]] = 0.0  # a pinned state: a column of stored zeros
    np.testing.assert_array_equal(sps.column_abs_sums(J), np.asarray(abs(J).sum(axis=0)).ravel())
    assert sps.column_abs_sums(J)[5] == 0.0
