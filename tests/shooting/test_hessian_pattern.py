"""The structure of a penalised fit's Hessian (:func:`.penalty.hessian_pattern`) made from one
window's block: the same CSC arrays as the product of the whole Jacobian's pattern, the
reference (what IPOPT is given, so the same iterates).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from rigs import spinning_seed004_50hz
from test_process_noise import _coast, _problem

from airbearing.analysis.discrepancy.replay import model_for, problem_for
from airbearing.analysis.shooting.functions import THETA_SLOTS
from airbearing.analysis.shooting.logs import make_windows, noise_floor, replay_data
from airbearing.analysis.shooting.penalty import _pattern, hessian_pattern
from airbearing.analysis.shooting.problem_functions import window_jacobian


def _by_product(fj, nd: int, nw: int) -> sp.csc_matrix:
    """``triu(J^T J + (Wp Jc)^T (Wp Jc))`` of the whole patterns, ones, sorted indices."""
    J = fj.pattern()
    Jc = _pattern(fj.defect_sparsity())
    H = J.T @ J
    if nw > 1:
        Wp = sp.block_diag([np.ones((nd, nd))] * (nw - 1), format="csc")
        H = H + (Wp @ Jc).T @ (Wp @ Jc)
    H = sp.triu(H, format="csc")
    H.data[:] = 1.0
    H.sort_indices()
    return H


def _platform(seconds: float, piece_s: float):
    """Seed 004's platform (dof 3, gyro and attitude) on linked pieces."""
    tb, log = spinning_seed004_50hz(seconds)
    datas = [replay_data(tb, log)]
    windows = make_windows(datas, window_s=piece_s, linked=True)
    return problem_for(model_for(tb, {}), datas, windows, noise_floor(datas))


@pytest.mark.parametrize(
    "make",
    [
        lambda: _problem([_coast(1.2, 2e-4, 30.0, 5), _coast(0.8, 2e-4, 12.0, 6)])[0],  # dof 1
        lambda: _problem([_coast(1.2, 2e-4, 8.0, 5)], piece_s=4.0)[0],  # two windows
        lambda: _platform(3.0, 0.5),  # dof 3: attitude and rate states
    ],
    ids=["dof1", "two-windows", "dof3"],
)
def test_pattern_from_one_window_is_the_whole_products(make):
    prob = make()
    nd, nw = prob.n_delta, prob.windows.n
    fj = window_jacobian(*prob._key(THETA_SLOTS), True)
    got, ref = hessian_pattern(fj, nd, nw), _by_product(fj, nd, nw)
    assert got.shape == ref.shape == (THETA_SLOTS + nd * nw,) * 2
    assert got.has_sorted_indices
    for name in ("indptr", "indices", "data"):
        a, b = getattr(got, name), getattr(ref, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    # the states of windows two apart never meet (the pattern is not trivially full)
    if nw > 2:
        assert not got[THETA_SLOTS, THETA_SLOTS + 2 * nd]
