"""A fit's Jacobian made in parts, in chunks of windows and without its unused slots
(:mod:`airbearing.analysis.shooting.problem_functions`, :meth:`ShootingProblem.jacobian_parts`):
the same numbers to the bit as the whole matrix they replace, which is the reference.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from test_process_noise import _coast, _problem

from airbearing.analysis.shooting import errors
from airbearing.analysis.shooting import problem_functions as pf
from airbearing.analysis.shooting import sparse as sps
from airbearing.analysis.shooting.fit import Fit, fit_jacobian, fit_jacobian_split
from airbearing.analysis.shooting.problem_arrays import _kept_columns
from airbearing.analysis.shooting.process_noise import KAPPA_GRID, set_intensity


def _same(got, ref) -> None:
    got, ref = sp.csc_matrix(got), sp.csc_matrix(ref)
    np.testing.assert_array_equal(got.indptr, ref.indptr)
    np.testing.assert_array_equal(got.indices, ref.indices)
    np.testing.assert_array_equal(got.data, ref.data)


def _point(prob, model, S):
    """A point of the problem away from zero (every entry of the Jacobian in play)."""
    rng = np.random.default_rng(3)
    delta = 1e-3 * rng.standard_normal((prob.n_delta, prob.windows.n))
    theta = np.full(S.shape[1], 1e-4)
    p = model.p0 + S @ theta
    return Fit(theta, theta, p, delta, 0.0, 0, 0, 0.0, 0)


def test_parts_chunks_and_empty_slots_are_the_whole_jacobians_numbers(monkeypatch):
    prob, model, S1 = _problem([_coast(1.2, 2e-4, 30.0, 5)], piece_s=2.0)
    set_intensity(prob, KAPPA_GRID[2])  # the defects whitened below the measurement rows
    S = np.zeros((model.n_p, 2))
    S[:, :1] = S1
    S[next(i for i in range(model.n_p) if S1[i, 0] == 0), 1] = 1.0  # another parameter
    at = _point(prob, model, S)
    r, J = prob.jacobian(at, S)  # the reference: every window at once
    monkeypatch.setattr(pf, "CHUNK_WINDOWS", 2)  # many chunks of windows
    r2, left, right = prob.jacobian_parts(at, S, 1)
    np.testing.assert_array_equal(r2, r)
    _same(left, J[:, :1])
    _same(right, J[:, 1:])
    # the parameter columns added into a dense array, the defects' rows too
    A = np.zeros((J.shape[0], 3))
    _, none, _ = prob.jacobian_parts(at, S, 2, right=False, dense=(A, np.arange(2), 1))
    assert none is None and not A[:, 0].any()
    np.testing.assert_array_equal(A[:, 1:], J[:, :2].toarray())
    # the whole matrix with its unused slots left empty, and without them
    v, Sp = prob._v(at.delta, S, at.theta)
    K = Sp.shape[1]
    fj = pf.window_jacobian(*prob._key(K), True)
    pb = at.p - S @ at.theta
    whole = fj(v, pb, Sp, prob._data)[1]
    used = fj(v, pb, Sp, prob._data, used=2)[1]
    assert used.shape == whole.shape and not used[:, 2:K].nnz
    keep = np.r_[np.arange(2), np.arange(K, whole.shape[1])]
    _same(_kept_columns(used, 2, K), whole[:, keep])
    _same(_kept_columns(whole, 2, K), whole[:, keep])


def test_columns_scaled_block_by_block_are_the_products():
    rng = np.random.default_rng(4)
    J = sp.random(400, 30, density=0.3, random_state=rng, format="csc")
    scale = 10.0 ** rng.uniform(-5, 5, 30)
    # the whole matrix's factors repeated for every entry, as before the blocks
    ref = J.copy()
    ref.data = J.data * np.repeat(scale, np.diff(J.indptr))
    old = sps.SCALE_BLOCK_ENTRIES
    try:
        for entries in (1, 7, 1 << 20):
            sps.SCALE_BLOCK_ENTRIES = entries
            got = sps.scale_columns(J.copy(), scale)
            np.testing.assert_array_equal(got.data, ref.data)
    finally:
        sps.SCALE_BLOCK_ENTRIES = old


def test_trailing_columns_are_the_slice_without_a_copy():
    """The honest errors' nuisance columns (``sparse.trailing_columns``) are ``J[:, k:]``
    to the bit and share ``J``'s entries; the projection made from them is the one made
    from the slice (a random sparse matrix with empty and full columns)."""
    rng = np.random.default_rng(5)
    J = sp.random(400, 40, density=0.3, format="csc", random_state=rng)
    J = sp.hstack([J[:, :3], sp.csc_matrix((400, 1)), J[:, 3:]], format="csc")
    for k in (1, 3, 4):
        got = sps.trailing_columns(J, k)
        _same(got, J[:, k:])
        assert np.shares_memory(got.data, J.data)
    k = 3
    At, An = J[:, :k].toarray(), J[:, k:]
    G = sp.csc_matrix(An.T @ An)
    c = np.sqrt(np.maximum(G.diagonal(), 1e-300))
    Dc = sp.diags(1.0 / c)
    coef = errors.solve_gram(Dc @ G @ Dc, np.asarray(An.T @ At) / c[:, None])
    np.testing.assert_array_equal(errors._projected(J, k), At - An @ (coef / c[:, None]))


def test_honest_errors_split_of_kept_blocks_is_the_whole_jacobians():
    """A fit that keeps its Jacobian's blocks (``J_made``: the round's columns made again,
    and its map ``E``; ``J_blocks``) has its parameter columns and window-state block
    handed to the honest errors without the whole matrix: the same numbers to the bit as
    :func:`fit_jacobian`'s columns, exact zeros of the product as +0.0, and the same
    projection; a fit keeping ``J`` whole, or another split, takes the matrix."""
    rng = np.random.default_rng(7)
    A = rng.standard_normal((300, 5))
    A[:40, 1] = 0.0
    A[40:60, 1] = -0.0
    E = np.zeros((5, 2))
    E[1, 0], E[3, 1] = -1.0, 2.0
    Jd = sp.random(300, 30, density=0.2, format="csc", random_state=rng)

    class Source:
        def columns_of(self, E):
            return A @ E, Jd

    theta = np.zeros(2)
    At0 = A @ E
    At0[:10, 0] = -0.0  # (a product's zero may carry either sign)
    for extra in ({"J_made": (Source(), E)}, {"J_blocks": (A, E, Jd)}, {"J_blocks": (At0, Jd)}):
        fit = Fit(theta, theta, theta, np.zeros((1, 1)), 0.0, 0, 0, 0.0, 0, extra=extra)
        J = fit_jacobian(fit)
        At, An = fit_jacobian_split(fit, 2)
        assert np.array_equal(np.signbit(At), np.signbit(J[:, :2].toarray()))
        np.testing.assert_array_equal(At, J[:, :2].toarray())
        # (its memory order too: BLAS's products with it round alike only on the same one)
        assert At.flags.f_contiguous == J[:, :2].toarray().flags.f_contiguous
        _same(An, J[:, 2:])
        np.testing.assert_array_equal(errors._projected_of(fit, 2), errors._projected(J, 2))
        assert fit_jacobian_split(fit, 3) is None
    whole = Fit(theta, theta, theta, np.zeros((1, 1)), 0.0, 0, 0, 0.0, 0, extra={"J": J})
    assert fit_jacobian_split(whole, 2) is None


def test_stacked_part_takes_out_dropped_slots_and_restacks_entries_outside(monkeypatch):
    """The window states' columns written into their stack over the defects' rows
    (:class:`.penalty.StackedPart`) are ``vstack_csc`` of the part and those rows to the
    bit: when the rows have every slot left for them, fewer (exact zeros a product
    dropped: the slots taken out) and one outside (stacked anew)."""
    from airbearing.analysis.shooting import penalty
    from airbearing.analysis.shooting.penalty import StackedPart

    monkeypatch.setattr(penalty, "DROP_BLOCK_ENTRIES", 5)  # slots taken out in many blocks
    prob, model, S = _problem([_coast(1.2, 2e-4, 30.0, 5)], piece_s=2.0)
    set_intensity(prob, KAPPA_GRID[2])
    at = _point(prob, model, S)
    v, Sp = prob._v(at.delta, S, at.theta)
    K = Sp.shape[1]
    fj = pf.window_jacobian(*prob._key(K), True)
    pb = at.p - S @ at.theta
    theta = np.arange(1, 2)  # one parameter slot, then the window states' columns
    _, (part,), _, Jc = fj(v, pb, Sp, prob._data, parts=[(theta, True)])
    cols = np.r_[theta, np.arange(K, fj.shape[1])]
    B = sp.csc_matrix(prob.penalty @ Jc)[:, cols]
    fewer = B.copy()
    fewer.data[::3] = 0.0
    fewer.eliminate_zeros()
    outside = B.tolil()
    outside[0, B.shape[1] - 1] = 7.0  # the first pair's defects never see the last window
    outside = sp.csc_matrix(outside)
    for rows in (B, fewer, outside):
        stacked = StackedPart(fj, theta, prob.penalty)
        _, (none,), _, _ = fj(v, pb, Sp, prob._data, parts=[stacked])
        assert none is None
        _same(stacked.stacked(rows), sps.vstack_csc(part, rows))
