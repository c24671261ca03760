"""The first round's row arrays on disk (:mod:`.first_round_arrays`): read back as they
were written, the search's answers the same to the bit as with them in memory, and the
search's directory gone however the search ends.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile

import numpy as np
import pytest
import scipy.sparse as sp
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy import first_round_arrays as fra
from airbearing.analysis.discrepancy import search as search_mod
from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.shooting import Fit
from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.testbed import load_testbed

ONLY = ["viscous_friction", "coulomb_friction", "aero_drag", "gyro_bias"]


def _fit(extra: dict) -> Fit:
    z = np.zeros(1)
    return Fit(theta=z, theta_std=z, p=z, delta=np.zeros((1, 1)), rss=0.0, n_res=1, n_free=1,
               gap=0.0, iterations=0, status="", level="converged", extra=extra)  # fmt: skip


def _same_sparse(a, b) -> None:
    assert type(a) is type(b) and a.shape == b.shape
    for name in ("data", "indices", "indptr"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        assert x.tobytes() == y.tobytes(), name
    flags = ("_has_sorted_indices", "_has_canonical_format")
    assert {k: a.__dict__.get(k) for k in flags} == {k: b.__dict__.get(k) for k in flags}


def test_arrays_come_back_as_they_were_written(tmp_path):
    rng = np.random.default_rng(1)
    r = rng.standard_normal(1000)
    J = sp.random(1000, 40, 0.05, format="csc", random_state=2)
    # 64-bit indices, as scipy makes them for a large matrix (its constructor would
    # narrow them), and one column's indices out of order
    J.indices, J.indptr = J.indices.astype(np.int64), J.indptr.astype(np.int64)
    lo, hi = J.indptr[3], J.indptr[4]
    assert hi - lo > 1
    J.indices[lo:hi] = J.indices[lo:hi][::-1].copy()
    J.data[lo:hi] = J.data[lo:hi][::-1].copy()
    J.has_sorted_indices = False
    N = np.asfortranarray(rng.standard_normal((40, 7)))
    P = object()  # the whitening: compared by identity, stays in memory
    at = (np.ones(2), np.ones((2, 3)), np.ones(4), P, np.ones(5))
    C = sp.random(30, 40, 0.1, format="csr", random_state=3)
    fit = _fit({"r": r, "J": J, "N": N, "linearised": (7, at, C), "S": np.eye(2)})
    store = fra.ArrayStore(tmp_path)
    away = store.set_aside(fit)
    assert fit.extra["r"] is r  # (the fit handed in is unchanged)
    assert all(fra._written(away.extra[k]) for k in fra.ON_DISK)
    assert away.extra["S"] is fit.extra["S"] and away.extra["linearised"][1] is at
    assert len(os.listdir(tmp_path)) == 1 + 3 + 1 + 3
    assert store.set_aside(away) is away  # nothing left in memory to write
    back = store.take_back(away)
    assert os.listdir(tmp_path) == []  # read back: its files removed
    assert back.extra["r"].dtype == r.dtype and back.extra["r"].tobytes() == r.tobytes()
    _same_sparse(back.extra["J"], J)
    assert back.extra["J"].indices.dtype == np.int64
    assert back.extra["N"].flags.f_contiguous and np.array_equal(back.extra["N"], N)
    serial, at_back, C_back = back.extra["linearised"]
    assert serial == 7 and at_back is at and at_back[3] is P
    _same_sparse(C_back, C)
    assert store.take_back(back) is back


def test_an_array_in_neither_order_stays_in_memory(tmp_path):
    r = np.arange(20.0)[::2]
    away = fra.ArrayStore(tmp_path).set_aside(_fit({"r": r}))
    assert away.extra["r"] is r and os.listdir(tmp_path) == []


def test_a_disk_that_refuses_them_leaves_them_in_memory(tmp_path, monkeypatch):
    r, J = np.ones(10), sp.eye(10, format="csc")
    calls = []

    def full(path, a, allow_pickle):  # the second file (J's data, after r) finds the disk full
        calls.append(path)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        with open(path, "wb") as f:
            f.write(b"x")

    monkeypatch.setattr(np, "save", full)
    away = fra.ArrayStore(tmp_path).set_aside(_fit({"J": J, "r": r}))
    assert away.extra["J"] is J  # its partly written files removed
    assert fra._written(away.extra["r"])
    assert [p.name for p in tmp_path.iterdir()] == [calls[0].name]  # r's alone


def test_without_a_temporary_directory_the_arrays_stay_in_memory(monkeypatch):
    def none(*args, **kwargs):
        raise FileNotFoundError("No usable temporary directory found")

    monkeypatch.setattr(tempfile, "TemporaryDirectory", none)
    with fra.search_files() as store:
        assert store is None


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_the_directory_is_removed_however_the_block_ends(error):
    with pytest.raises(error), fra.search_files() as store:
        store.set_aside(_fit({"r": np.ones(3)}))
        where = store.directory
        assert os.listdir(where)
        raise error
    assert not where.exists() and str(where) not in fra._LIVE


def test_a_hard_exit_removes_the_directories_of_running_searches():
    # the command line's exit on Ctrl-C (os._exit) runs no clean-up of the search's own
    with fra.search_files() as store:
        store.set_aside(_fit({"r": np.ones(3)}))
        fra.remove_left()
        assert not store.directory.exists()
    assert not fra._LIVE


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_a_search_that_fails_leaves_no_files(monkeypatch, tmp_path, error):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    seen = []

    def boom(search, sel, *args):  # the named effects' stage, after the rounds
        seen.append(sorted(os.listdir(sel.store.directory)))
        raise error

    monkeypatch.setattr(search_mod, "_named", boom)
    tb = load_testbed("cmg-yaw")
    run = slew(tb, angle_deg=30.0, duration=3.0, effects={"aero_drag": 2e-3})
    with pytest.raises(error):
        discrepancy(tb, run.log, max_effects=1)
    assert seen and seen[0]  # the first round's arrays were on disk
    assert os.listdir(tmp_path) == []


@pytest.mark.slow  # two searches of two rounds on a 6 s log: about 5 s (16 s compiling)
def test_the_first_rounds_honest_errors_are_the_same_bits_on_disk(monkeypatch, handed_rounds):
    tb, log = spinning_seed004_50hz(6.0, {"viscous_friction": 1e-5, "aero_drag": 3e-5})
    written = []
    set_aside = fra.ArrayStore.set_aside

    def spy(self, fit):
        written.extend(k for k in fra.ON_DISK if k in fit.extra and not fra._written(fit.extra[k]))
        return set_aside(self, fit)

    monkeypatch.setattr(fra.ArrayStore, "set_aside", spy)
    handed = handed_rounds  # each round's results as handed over, before it is decided
    on_disk = discrepancy(tb, log, max_effects=2, only=ONLY)
    # an IPOPT fit's Jacobian and linearisation and every candidate's residual were on disk
    assert {"r", "J", "linearised"} <= set(written)
    # ... the first round's from when each candidate ended, before the round was decided
    first = [c.fit for c in handed[0] if c.fit is not None]
    assert first and all(fra._written(f.extra["r"]) for f in first)
    assert any(fra._written(f.extra.get("J")) for f in first)

    @contextlib.contextmanager
    def in_memory():
        yield None

    monkeypatch.setattr(search_mod, "search_files", in_memory)
    written.clear()
    kept = discrepancy(tb, log, max_effects=2, only=ONLY)
    assert not written
    assert len(on_disk.rounds) >= 2 and len(on_disk.rounds[0]) == len(kept.rounds[0])
    errors = 0
    for a, b in zip(on_disk.rounds[0], kept.rounds[0], strict=True):
        assert a.label == b.label
        for name in ("std", "std_white", "crlb", "efficiency"):
            x, y = getattr(a, name), getattr(b, name)
            assert np.asarray(x, float).tobytes() == np.asarray(y, float).tobytes(), a.label
            errors += x is not None
    assert errors > 0
    assert json.dumps(on_disk.to_json(), default=str) == json.dumps(kept.to_json(), default=str)
