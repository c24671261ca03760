"""What a long discrepancy search keeps in memory, and that keeping less changes nothing.

- The screen's Jacobian (a slot per candidate parameter, wider than any fit's) makes its
  CSC index arrays per call instead of keeping them in the cached window function
  (``problem_functions.KEPT_INDEX_SLOTS``): its columns must be those of a fit's Jacobian.
  A fit's slot count keeps them once a whole Jacobian is asked for, not before (the fits
  evaluate their used slots' part), and only while a matrix made of them is alive.
- A later round's candidates let go of their per-row arrays once the round is decided
  (``selection.ROW_ARRAYS``), one that cannot be named as soon as it ends; the first
  round's keep them until their honest errors are taken at the end (a step-judged one
  what makes its columns, from when it ends), each then letting go; the fit the search
  goes on from keeps them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy.candidates import candidates_for
from airbearing.analysis.discrepancy.replay import prepare
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.discrepancy.search_state import _Search
from airbearing.analysis.discrepancy.selection import ROW_ARRAYS
from airbearing.analysis.shooting import THETA_SLOTS
from airbearing.analysis.shooting.problem_functions import (
    KEPT_INDEX_SLOTS,
    _KeptIndex,
    window_jacobian,
)

#: The candidates of the searches on this rig in test_discrepancy_workers.py and
#: test_screen_far_candidates.py: one Model (every candidate at zero), so one compiled step
#: Jacobian for all of them; what is checked here does not depend on which candidates
ONLY = ["viscous_friction", "coulomb_friction", "aero_drag", "gyro_bias"]


def test_a_wide_jacobian_makes_its_index_arrays_per_call():
    assert KEPT_INDEX_SLOTS == THETA_SLOTS  # (functions.py imports problem_functions)
    tb, log = spinning_seed004_50hz(2.0)
    datas, windows, floor = prepare(tb, [log])
    # the candidates of test_discrepancy_workers.py's search (its compiled Model is shared)
    cands = candidates_for(tb, datas, ONLY)
    search = _Search(tb, datas, windows, floor, cands, 0, None)
    pb = search.problem(False)
    nominal = pb.fit(search.models[False].p0.copy(), name="nominal")
    S = search.S(False, cands)  # every candidate's columns
    S = np.hstack([S, S[:, :2]])  # wider than the slots of a fit
    k = S.shape[1]
    assert k > THETA_SLOTS
    at = replace(nominal, theta=np.zeros(k))
    _, J_wide = pb.jacobian(at, S)
    wide = window_jacobian(*pb._key(k), pb.link)
    narrow = window_jacobian(*pb._key(THETA_SLOTS), pb.link)
    # a fit evaluates its used slots' part only: the whole arrays are not made for it
    assert wide._index is None and narrow._index is None
    # the first columns are a fit's (the same window function's derivatives, exactly)
    _, J_fit = pb.jacobian(replace(nominal, theta=np.zeros(2)), S[:, :2])
    assert wide._index is None and narrow._index is not None  # kept once asked for
    # ... while a matrix made of them is alive (the fit's J above was a copy of columns)
    assert _KeptIndex.get(narrow._index) is None
    v, Sp = pb._v(nominal.delta, S[:, :2], np.zeros(2))
    J = narrow(v, nominal.p, Sp, pb._data)[1]
    kept = _KeptIndex.get(narrow._index)
    assert np.shares_memory(kept[0], J.indices) and np.shares_memory(kept[1], J.indptr)
    del J, kept
    assert _KeptIndex.get(narrow._index) is None
    assert J_wide.shape[0] == J_fit.shape[0]
    np.testing.assert_array_equal(J_wide[:, :2].toarray(), J_fit[:, :2].toarray())
    np.testing.assert_array_equal(J_wide[:, k:].toarray(), J_fit[:, 2:].toarray())
    P = wide.pattern()
    assert P.shape == wide.shape and P.nnz == wide.index_arrays()[0].size


@pytest.mark.slow  # one search of two rounds on a 6 s log: about 3 s (16 s compiling)
def test_a_decided_later_round_lets_go_of_its_per_row_arrays(handed_rounds):
    tb, log = spinning_seed004_50hz(6.0, {"viscous_friction": 1e-5, "aero_drag": 3e-5})
    # each round's results as the round hands them over, before it is decided
    handed = handed_rounds
    res = discrepancy(tb, log, max_effects=2, only=ONLY)
    assert len(handed) >= 2
    # the first round's step-judged fits keep what makes their columns, not the columns,
    # and every first-round fit keeps its residual and Jacobian (or what makes it) for its
    # honest errors
    first = [c.fit for c in handed[0] if c.fit is not None]
    assert first and not any("J_blocks" in f.extra for f in first)
    assert all("r" in f.extra for f in first)
    assert all(any(k in f.extra for k in ("J", "J_made")) for f in first)
    # a later round's candidate that cannot be named (e.g. pinned at its bound) let go of
    # its per-row arrays when it ended, before the round was decided
    for rnd in handed[1:]:
        for c in rnd:
            if c.fit is not None and not c.nameable:
                assert not any(k in c.fit.extra for k in ROW_ARRAYS), c.label
    assert any(c.fit is not None and not c.nameable for rnd in handed[1:] for c in rnd)
    assert len(res.rounds) >= 2
    # ... which, the last to read them, let them go: the search's first round keeps none
    # (its values and honest errors stay)
    done = [c for c in res.rounds[0] if c.fit is not None]
    assert done and not any(k in c.fit.extra for c in done for k in ROW_ARRAYS)
    assert all(c.std is not None for c in done if c.value is not None)
    stripped = 0
    for rnd in res.rounds[1:]:
        keeping = [
            c for c in rnd if c.fit is not None and any(k in c.fit.extra for k in ROW_ARRAYS)
        ]
        # only the round's pick (an IPOPT fit the search went on from) keeps them
        assert len(keeping) <= 1, [c.label for c in keeping]
        assert all(c.nameable and c.status != "screened" for c in keeping)
        stripped += sum(1 for c in rnd if c.fit is not None) - len(keeping)
    assert stripped > 0
