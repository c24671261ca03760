"""The lag score's projection on kept rows (zeros in a copy of the values, the index arrays
shared) gives the same bits as the least squares on a copy of the kept rows."""

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from airbearing.analysis.discrepancy.lag_score import RIDGE, _Projection
from airbearing.analysis.shooting.sparse import gram


def _on_kept_rows(A, keep, v):
    """The reference: the kept rows copied, then the same normal equations."""
    Ak = sp.csc_matrix(A[keep])
    G = sp.csc_matrix(gram(Ak))
    c = np.sqrt(np.maximum(G.diagonal(), 0.0))
    c = np.where(c > 0, c, 1.0)
    Dc = sp.diags(1.0 / c)
    lu = splu(sp.csc_matrix(Dc @ G @ Dc + RIDGE * sp.identity(G.shape[0])))
    a = lu.solve((Ak.T @ v[keep]) / c) / c
    return a, Ak @ a


@pytest.mark.parametrize("seed", range(12))
def test_projection_is_the_kept_rows_least_squares_to_the_bit(seed):
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(200, 2000)), int(rng.integers(3, 30))
    A = sp.random(m, n, density=rng.uniform(0.02, 0.4), format="csc", random_state=rng)
    A.data = rng.standard_normal(A.nnz) * 10.0 ** rng.integers(-6, 6, A.nnz)
    keep = rng.random(m) > rng.uniform(0.05, 0.6)
    # a column whose only entries are on left-out rows: its normal-matrix entries vanish
    A = sp.hstack([A, sp.csc_matrix((np.ones(2), (np.flatnonzero(~keep)[:2], [0, 0])),
                                    shape=(m, 1))], format="csc")  # fmt: skip
    v = rng.standard_normal(m)
    v[~keep] = np.inf  # never read
    proj = _Projection(A, keep)
    a, fitted = proj.coef(v), proj.fitted(proj.coef(v))
    a_ref, fitted_ref = _on_kept_rows(A, keep, v)
    assert np.array_equal(a, a_ref)
    assert np.array_equal(fitted, fitted_ref)
