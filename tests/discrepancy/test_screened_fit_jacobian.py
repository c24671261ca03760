"""A candidate judged on its Gauss-Newton step keeps the round's window-state columns, not a
copy (``Fit.extra["J_blocks"]``, :func:`airbearing.analysis.shooting.fit_jacobian`).

On a 3 s, 50 Hz seed-004 platform oscillation (viscous friction 1e-5 N m s hidden): the
step's Jacobian made from its blocks must be the problem's Jacobian at the current fit in
the candidate's parameters, and the honest errors taken from the blocks the same numbers as
from that matrix held whole.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy import linearisation
from airbearing.analysis.discrepancy.candidates import candidates_for
from airbearing.analysis.discrepancy.linearisation import linearise
from airbearing.analysis.discrepancy.replay import prepare
from airbearing.analysis.discrepancy.search_state import _Search
from airbearing.analysis.shooting import fit_jacobian, theta_errors
from airbearing.analysis.shooting.errors import honest_errors

ONLY = ["viscous_friction", "coulomb_friction", "aero_drag", "gyro_bias"]


def test_a_screened_fit_shares_the_window_state_columns():
    tb, log = spinning_seed004_50hz(3.0)
    datas, windows, floor = prepare(tb, [log])
    # the Model of the searches on this rig (test_discrepancy_workers.py: every candidate
    # of ONLY at zero, one compiled step Jacobian for them all); the frictions are judged
    search = _Search(tb, datas, windows, floor, candidates_for(tb, datas, ONLY), 0, None)
    cands = [c for c in search.cands if c.name in ("viscous_friction", "aero_drag")]
    pb = search.problem(False)
    nominal = pb.fit(search.models[False].p0.copy(), name="nominal")
    lin = linearise(pb, nominal, search.S(False, []), cands)
    for c in cands:
        E = lin.columns(c.params, c.tie)
        st = lin.step(E, [], [], c.lower, c.upper)
        fit = lin.fit_of(st, c.k)
        assert "J" not in fit.extra, c.label
        assert fit.extra["J_blocks"][-1] is lin.Jd, c.label  # shared, not copied
        assert fit.extra["J_blocks"][0] is lin.A, c.label
        J = fit_jacobian(fit)
        _, J_ref = pb.jacobian(replace(nominal, theta=np.zeros(c.k)), search.S(False, [c]))
        assert J.shape == J_ref.shape, c.label
        # the screen combines unit-parameter columns (A E) where the problem differentiates
        # in the tied ones directly: equal to round-off of the largest entry
        diff = abs(J - sp.csc_matrix(J_ref)).max()
        assert diff <= 1e-9 * abs(J_ref).max(), (c.label, diff)
        # the step's own errors, from the round's shared Gram pieces (the step's matrix is
        # never made), are those of that matrix to round-off: the same sums in another
        # order (at most 7e-11 relative measured on the 10,001-row 50 Hz log's candidates;
        # 1e-8 allowed)
        s2 = fit.rss / max(fit.n_res - fit.n_free, 1)
        std_ref, cov_ref, why_ref = theta_errors(J, c.k, s2)
        np.testing.assert_allclose(fit.theta_std, std_ref, rtol=1e-8)
        np.testing.assert_allclose(fit.cov, cov_ref, rtol=1e-8, atol=1e-8 * abs(cov_ref).max())
        assert fit.not_identifiable == why_ref, c.label
        # the honest errors from the blocks are those of the matrix held whole, exactly
        whole = replace(fit, extra={"r": fit.extra["r"], "J": J})
        a, b = honest_errors(pb, fit, c.k), honest_errors(pb, whole, c.k)
        np.testing.assert_array_equal(a.std, b.std)
        np.testing.assert_array_equal(a.crlb, b.crlb)


def test_columns_made_again_are_the_rounds_to_the_bit(monkeypatch):
    """A step-judged fit's parameter columns made again for its honest errors
    (:meth:`.linearisation.Columns.columns_of`) are the round's ``A E`` to the bit, though only
    the columns of ``A`` that ``E`` reads are made (one-value forms tie three columns), and
    the window states' columns are the round's. The columns of the fits still expected
    (their maps ``E`` held) are made with them within ``KEPT_COLUMNS`` and kept with the
    window states' for the next fit, which makes nothing again; those of a fit let go are
    not made, and the last fit expected lets them all go."""
    tb, log = spinning_seed004_50hz(3.0)
    datas, windows, floor = prepare(tb, [log])
    search = _Search(tb, datas, windows, floor, candidates_for(tb, datas, ONLY), 0, None)
    pb = search.problem(False)
    nominal = pb.fit(search.models[False].p0.copy(), name="nominal")
    lin = linearise(pb, nominal, search.S(False, []), search.cands)
    src = lin.made
    made = []
    make = linearisation.Columns.make

    def counted(self, keep=None, states=True):
        made.append((None if keep is None else list(keep), states))
        return make(self, keep, states)

    monkeypatch.setattr(linearisation.Columns, "make", counted)
    linearisation.forget_columns()
    tied, forms = 0, {}
    for c in search.cands:
        E = lin.columns(c.params, c.tie)
        used = np.flatnonzero(np.any(E != 0, axis=1))
        forms.setdefault(tuple(used), (c.params, c.tie))
        tied += bool(np.any(np.count_nonzero(E, axis=0) > 1))
        At, Jd = src.columns_of(E)
        np.testing.assert_array_equal(At + 0.0, lin.A @ E + 0.0)  # (a zero of either sign)
        assert (Jd != lin.Jd).nnz == 0 and Jd.shape == lin.Jd.shape, c.label
        assert made[-1][0] == list(used) and used.size < lin.A.shape[1], c.label
        assert linearisation._KEPT[0] is None, c.label  # (no other fit expected)
    assert tied, "no one-value form among the candidates"
    (u1, f1), (u2, f2), (u3, f3) = list(forms.items())[:3]
    E1, E1b, E2, E3 = (lin.columns(*f) for f in (f1, f1, f2, f3))
    monkeypatch.setattr(linearisation, "KEPT_COLUMNS", len(set(u1) | set(u2) | set(u3)))
    for E in (E1, E1b, E2, E3):
        src.expect(E)
    del E, E3  # (let go: no longer asks)
    made.clear()
    At, _ = src.columns_of(E1)
    assert made == [(sorted(set(u1) | set(u2)), True)]
    kept = linearisation._KEPT[0]
    assert kept[0] is src and list(kept[2]) == sorted(set(u1) | set(u2))
    At1b, _ = src.columns_of(E1b)
    del E1, E1b
    At2, _ = src.columns_of(E2)
    assert len(made) == 1  # (the window states' columns too: made once)
    assert linearisation._KEPT[0] is None  # (E2 the last expected)
    np.testing.assert_array_equal(At + 0.0, lin.A @ lin.columns(*f1) + 0.0)
    np.testing.assert_array_equal(At2 + 0.0, lin.A @ lin.columns(*f2) + 0.0)


def test_the_product_made_back_block_by_block_is_the_whole_products():
    """:func:`.linearisation._product`: ``A E`` from the columns of ``A`` that ``E`` reads, made
    back a block of rows at a time in ``A``'s width and order, is the product with the
    whole ``A`` to the bit (BLAS adds a tied column's terms by their positions in ``A``:
    the product of the columns alone differs in the last bits). Sizes within one BLAS
    thread (400 rows of 20), blocks of 64 rows and a shorter last one."""
    rng = np.random.default_rng(3)
    for order in ("C", "F"):
        A = np.asarray(
            rng.standard_normal((400, 20)) * 10.0 ** rng.integers(-6, 3, 20), order=order
        )
        for k, nz in ((1, 3), (1, 5), (2, 4), (3, 1)):
            E = np.zeros((20, k))
            for c in range(k):
                E[rng.choice(20, nz, replace=False), c] = rng.choice([1.0, -1.0, 0.5, 3.0], nz)
            have = np.flatnonzero(np.any(E != 0, axis=1))
            have = np.union1d(have, [19])  # (a column made but not read: zero in E)
            got = linearisation._product(A[:, have], have, 20, E, order, rows=64)
            np.testing.assert_array_equal(got + 0.0, A @ E + 0.0)
