"""The shooting engine's pieces that keep long logs linear in time and memory.

Oracles: CasADi's own Jacobian of the whole residual (``ca.jacobian`` of the problem's
residual Function, exact AD) for the window blocks placed by NumPy; CasADi's ordinary call
for the zero-copy evaluation; ``scipy.sparse.vstack`` for the row stacking; a plain map for
the windows mapped a few at a time; and the dense SVD null space (orthonormal) for the
sparse-LU basis of the continuity, through the parameter errors it gives (the Schur
complement does not depend on the basis of the eliminated directions). Small problems in
CasADi's virtual machine: no compiler, a few seconds.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import scipy.sparse as sp

from airbearing.analysis.identification.data import prepare_platform_logs
from airbearing.analysis.identification.oe_problem import platform_windows
from airbearing.analysis.identification.platform import seed004_testbed
from airbearing.analysis.identification.regression import PARAM_NAMES
from airbearing.analysis.shooting import ShootingProblem, null_space_basis, theta_errors
from airbearing.analysis.shooting.constrained import _dense_null_space_basis
from airbearing.analysis.shooting.functions import (
    _problem_functions,
    evaluate,
    map_windows,
    vstack_csc,
)
from airbearing.analysis.shooting.problem_functions import _data_shapes, residual_function
from airbearing.analysis.shooting.window_functions import _window_functions
from airbearing.analysis.simulation.scenarios import free_oscillation
from airbearing.models.model import build_model

RUNS = [
    ((-0.307, 0.189, -1.5), (0.012, -0.018, 0.010)),
    ((0.15, 0.45, 1.4), (0.004, 0.022, -0.016)),
]


@pytest.fixture(scope="module")
def linked():
    """A linked problem of two 3 s logs in 7 pieces each (an odd count), 9 parameter slots,
    at a point off the data (so nothing is zero by accident)."""
    tb = seed004_testbed()
    logs = [
        free_oscillation(tb, initial_rate=w, sliders=s, duration=3.0, seed=i).log
        for i, (w, s) in enumerate(RUNS)
    ]
    data = prepare_platform_logs(tb, logs)
    model = build_model(tb)
    windows = platform_windows(model, data, 0.45)
    problem = ShootingProblem(
        model, windows, ("rate", "quat"), 7.7e-4, 1e-3, jit=False, theta_slots=9
    )
    idx = np.asarray(model.index(list(PARAM_NAMES), "p"))
    S = np.zeros((model.n_p, 9))
    S[idx, np.arange(9)] = 1.0
    rng = np.random.default_rng(3)
    theta = rng.normal(scale=1e-4, size=9)
    delta = rng.normal(scale=1e-3, size=(problem.n_delta, windows.n))
    v, Sp = problem._v(delta, S, theta)
    return problem, model, v, Sp


def test_window_blocks_are_casadis_jacobian(linked):
    """The window blocks placed by NumPy are CasADi's exact Jacobian of the whole residual
    and of the defects (AD of the same expressions: 1e-12 relative)."""
    problem, model, v, Sp = linked
    _, fj, _ = _problem_functions(*problem._key(Sp.shape[1]), True)
    fr = residual_function(*problem._key(Sp.shape[1]), True)
    vs = ca.MX.sym("v", v.size)
    r, c = fr(vs, model.p0, Sp, problem._data)
    oracle = ca.Function("whole_jacobian", [vs], [ca.jacobian(r, vs), ca.jacobian(c, vs)])
    Jr, Jc = (np.asarray(ca.densify(m)) for m in oracle(v))
    rm, J, cm, C = fj(v, model.p0, Sp, problem._data)
    assert J.shape == Jr.shape and C.shape == Jc.shape
    scale = np.abs(Jr).max()
    np.testing.assert_allclose(J.toarray(), Jr, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(C.toarray(), Jc, rtol=0, atol=1e-12 * np.abs(Jc).max())
    np.testing.assert_array_equal(rm, np.asarray(fr(v, model.p0, Sp, problem._data)[0]).ravel())
    np.testing.assert_array_equal(cm, np.asarray(fr(v, model.p0, Sp, problem._data)[1]).ravel())


def test_zero_copy_evaluation_is_the_call(linked):
    """``evaluate`` writes exactly what CasADi's call returns."""
    problem, model, v, Sp = linked
    fr = residual_function(*problem._key(Sp.shape[1]), True)
    got = evaluate(fr, v, model.p0, Sp, problem._data)
    want = fr(v, model.p0, Sp, problem._data)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b).ravel())


# free windows on one window only: the fixture's data vector is that of linked windows
@pytest.mark.parametrize(("link", "nw"), [(True, None), (True, 1), (False, 1)])
def test_the_windows_run_from_numpy_are_the_mapped_functions_to_the_bit(linked, link, nw):
    """The residual (and the defects) and the outputs of all windows run window by window
    from NumPy (``WindowResidual``, ``WindowOutputs``: no CasADi expression of all the
    windows) are those of the windows mapped in one CasADi Function, to the bit; on an odd
    window count (a pair at a time, the last alone), on free windows and on one window."""
    problem, model, v, Sp = linked
    key = list(problem._key(Sp.shape[1]))
    data = problem._data
    if nw == 1:  # the first window alone: its entries of v and of the data vector
        nw0, L, K = key[2], key[1], Sp.shape[1]
        key[2] = 1
        v = v[: K + problem.n_delta]
        shapes = _data_shapes(model, L, nw0, problem.n_rate, True, 2)
        pieces, at = [], 0
        for a, b in shapes:
            cols = b // nw0 if b % nw0 == 0 and b >= nw0 else b
            pieces.append(data[at : at + a * b].reshape(a, b, order="F")[:, :cols])
            at += a * b
        if not link:
            pieces.pop(-2)  # no hand-over row selector
        data = np.concatenate([p.reshape(-1, order="F") for p in pieces])
    fr, _, fy = _problem_functions(*key, link)
    want = residual_function(*key, link).call([v, model.p0, Sp, data])
    got = evaluate(fr, v, model.p0, Sp, data)
    assert len(got) == len(want) == (2 if link else 1)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a, np.asarray(b).ravel())
    # the outputs: the window output function mapped over the windows
    win_y = _window_functions(*key[:1], key[1], key[3], *key[4:7], link)[2]
    nd, K = problem.n_delta, Sp.shape[1]
    D = v[K:].reshape(nd, key[2], order="F")
    shapes = _data_shapes(model, key[1], key[2], problem.n_rate, link, 2)
    x0, U, dt = (data[a : a + n] for a, n in _offsets(shapes)[:3])
    Y = win_y.map(key[2])(D, x0.reshape(shapes[0], order="F"), U.reshape(shapes[1], order="F"),
                          dt.reshape(shapes[2], order="F"), model.p0, Sp, v[:K])  # fmt: skip
    got_y = evaluate(fy, v, model.p0, Sp, data)[0].reshape(fy.size_out(0), order="F")
    np.testing.assert_array_equal(got_y, np.asarray(Y))


def _offsets(shapes) -> list:
    """``(offset, entries)`` of each piece of a data vector (``_data_shapes``)."""
    out, at = [], 0
    for a, b in shapes:
        out.append((at, a * b))
        at += a * b
    return out


def test_windows_mapped_a_few_at_a_time_equal_one_map():
    """``map_windows`` (threaded pairs in a serial map, an odd window alone) gives a plain
    map's outputs for per-window and shared inputs."""
    x, p = ca.SX.sym("x", 2, 3), ca.SX.sym("p", 2)
    f = ca.Function("f", [x, p], [ca.sum2(x) * p[0] + p[1], x * p[1]])
    nw = 7
    X = np.arange(2 * 3 * nw, dtype=float).reshape(2, 3 * nw)
    P = np.array([0.5, -2.0])
    want = f.map(nw)(X, P)
    xs = ca.MX.sym("X", 2, 3 * nw)
    got = ca.Function("g", [xs], map_windows(f, nw, [xs, ca.DM(P)]))(X)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_row_stacking_is_scipys():
    rng = np.random.default_rng(0)
    A = sp.random(50, 12, density=0.3, random_state=rng, format="csc")
    B = sp.random(4, 12, density=0.4, random_state=rng, format="csc")
    got = vstack_csc(A, B)
    want = sp.vstack([A, B]).tocsc()
    np.testing.assert_array_equal(got.toarray(), want.toarray())
    assert got.has_sorted_indices or np.all(np.diff(got.indices[: got.indptr[1]]) > 0)
    # stacked in place of the given matrix (its arrays let go as they are copied): the
    # same arrays, some columns of B empty, some of A too
    A.data[A.indptr[3] : A.indptr[4]] = 0.0
    A.eliminate_zeros()
    B = sp.random(3, 12, density=0.3, random_state=rng, format="csc")
    ref = vstack_csc(A, B)
    given = A.copy()
    got = vstack_csc(given, B, consume=True)
    for name in ("data", "indices", "indptr"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name))
    np.testing.assert_array_equal(got.toarray(), sp.vstack([A, B]).toarray())
    assert given.data is None and given.indices is None  # nothing of it held any more


def test_sparse_null_space_gives_the_dense_errors(linked):
    """The continuity's null space by one sparse LU (the continued windows follow the free
    ones) spans the dense SVD's: ``Jc N = 0``, and the parameters' errors in it are the
    same (1e-8 relative)."""
    problem, model, v, Sp = linked
    _, fj, _ = _problem_functions(*problem._key(Sp.shape[1]), True)
    _, J, _, C = fj(v, model.p0, Sp, problem._data)
    Jc = C[problem.link_rows]
    k = 9
    N = null_space_basis(Jc, k, problem.n_delta)
    N0 = _dense_null_space_basis(Jc.toarray(), k)
    assert N.shape == N0.shape
    assert np.abs(Jc @ N).max() <= 1e-9 * np.abs(Jc).max() * np.abs(N).max()
    std, cov, _ = theta_errors(J @ N, k, 1.0)
    std0, cov0, _ = theta_errors(J @ N0, k, 1.0)
    np.testing.assert_allclose(std, std0, rtol=1e-8)
