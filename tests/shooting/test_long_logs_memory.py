"""The sparse Gram matrix of a fit's errors made block of columns by block (``fit.gram``):
the same matrix to the bit as scipy's whole product, with one copy of the Jacobian less.

The Jacobian has the shape of a shooting fit's (a few dense parameter columns, then every
window's own block of initial-state columns), column-scaled as :func:`theta_errors` scales
it; entries over 14 decades, so that a sum taken in another order would differ in its last
bits.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from airbearing.analysis.shooting.fit import gram, theta_errors
from airbearing.analysis.shooting.sparse import GRAM_BLOCKS


def _window_jacobian(nw=40, n=120, nd=6, k=3, seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((nw * n, k)) * 10.0 ** rng.uniform(-7, 7, size=k)
    A[rng.random(A.shape) < 0.05] = 0.0  # rows that do not see a parameter (weight 0)
    blocks = [sp.csc_matrix(rng.standard_normal((n, nd)) * 10.0 ** rng.uniform(-3, 3, nd))
              for _ in range(nw)]  # fmt: skip
    return sp.hstack([sp.csc_matrix(A), sp.block_diag(blocks, format="csc")]).tocsc()


def test_the_gram_matrix_by_column_blocks_is_scipys_to_the_bit():
    for seed in range(3):
        J = _window_jacobian(seed=seed)
        c = np.sqrt(np.asarray(J.power(2).sum(axis=0)).ravel())
        Js = J @ sp.diags(1.0 / c)
        assert Js.shape[1] > GRAM_BLOCKS
        ref = sp.csc_matrix(Js.T @ Js)
        got = gram(Js)
        assert sp.isspmatrix_csc(got) or got.format == "csc"
        np.testing.assert_array_equal(got.indptr, ref.indptr)
        np.testing.assert_array_equal(got.indices, ref.indices)
        np.testing.assert_array_equal(got.data, ref.data)


def test_gram_of_a_dense_or_narrow_jacobian_is_the_product():
    J = _window_jacobian(nw=1, n=50, nd=2, k=1)  # 3 columns: one block
    np.testing.assert_array_equal(gram(J).toarray(), (J.T @ J).toarray())
    D = J.toarray()
    np.testing.assert_array_equal(gram(D), D.T @ D)


def test_theta_errors_are_those_of_the_whole_product():
    # the errors of the first k columns with the windows' states eliminated, against the
    # Schur complement formed densely (agreement to rounding: another order of sums)
    J = _window_jacobian(seed=4)
    k = 3
    std, cov, reasons = theta_errors(J, k, 1.0)
    assert not any(reasons)
    D = J.toarray()
    F = D.T @ D
    Fr = F[:k, :k] - F[:k, k:] @ np.linalg.solve(F[k:, k:], F[k:, :k])
    np.testing.assert_allclose(std, np.sqrt(np.diag(np.linalg.inv(Fr))), rtol=1e-8)


def test_a_small_block_stacked_below_keeps_32_bit_indices():
    from airbearing.analysis.shooting.sparse import vstack_csc

    J = _window_jacobian(nw=5, n=30, seed=7)
    B = sp.random(4, J.shape[1], density=0.3, random_state=2, format="csc")
    got = vstack_csc(J, B)
    ref = sp.vstack([J, B]).tocsc()
    ref.sort_indices()
    assert got.indices.dtype == np.int32 and got.indptr.dtype == np.int32
    np.testing.assert_array_equal(got.indptr, ref.indptr)
    np.testing.assert_array_equal(got.indices, ref.indices)
    np.testing.assert_array_equal(got.data, ref.data)
