"""What the engine keeps of a log through a whole search: one copy of the samples, and the
per-row bookkeeping in the narrowest integers (structural checks, not sizes).

- Reading a log hands the free pages of Arrow's memory pool back (an hour of 50 Hz
  three-axis samples left ~90 MB of them resident through the whole search).
- The replay's data keep the log they were given when it was read or made with the very
  testbed replayed (validated against it already), not a second, validated copy of its
  samples (and no pandas table made of its arrays).
- A shooting problem's group, component and sample index of every residual row are 8 and
  32 bit integers (one entry per residual row: 10^6 on an hour of samples).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy.replay import prepare, problem_for
from airbearing.analysis.shooting.logs import replay_data
from airbearing.io.log import Log, read_log, write_log
from airbearing.models.model import build_model


class _SpyPool:
    """Arrow's default pool as far as ``log_read.release_arrow_memory`` asks it."""

    def __init__(self, backend: str) -> None:
        self.backend_name, self.released = backend, 0

    def release_unused(self) -> None:
        self.released += 1


def _written(tmp_path, duration: float = 1.0):
    tb, log = spinning_seed004_50hz(duration)
    return tb, write_log(log, tmp_path / "run.csv")


def test_reading_a_log_gives_arrows_free_pages_back(tmp_path, monkeypatch):
    tb, path = _written(tmp_path)
    for backend, want in (("mimalloc", 1), ("jemalloc", 1), ("system", 0)):
        spy = _SpyPool(backend)
        monkeypatch.setattr(pa, "default_memory_pool", lambda spy=spy: spy)
        read_log(path, tb)
        # the system pool (glibc's malloc, kept for reuse by some commands) is left alone
        assert spy.released == want, backend


def test_the_replay_keeps_the_log_read_with_its_testbed(tmp_path):
    tb, path = _written(tmp_path)
    log = read_log(path, tb)
    d = replay_data(tb, log)
    assert d.log is log
    assert log._frame is None  # its arrays: no pandas table made of them
    # a log read without the testbed is validated against it: a copy
    other = read_log(path)
    d2 = replay_data(tb, other)
    assert d2.log is not other and d2.log.testbed is tb
    for name in ("t", "u", "att", "w", "mask"):
        np.testing.assert_array_equal(getattr(d, name), getattr(d2, name))


def test_a_problems_row_bookkeeping_is_narrow():
    tb, log = spinning_seed004_50hz(2.0)
    datas, windows, floor = prepare(tb, [Log(log.data, log.source, tb)])
    pb = problem_for(build_model(tb), datas, windows, floor)
    assert pb.group.dtype == np.int8 and pb.component.dtype == np.int8
    assert pb.sample.dtype == np.int32
    n = pb.n_meas
    assert pb.group.size == pb.component.size == pb.sample.size == n
    # the sample of each row: its window's first row plus its row within the window
    L = windows.length
    assert pb.sample.min() >= 0 and pb.sample.max() < windows.n * L
    assert np.all(np.diff(pb.sample[:: pb.n_win_res]) == L)


def test_a_fits_column_norms_are_those_of_the_stacked_matrix_to_the_bit():
    """A penalised fit's column scaling from the window Jacobian and the weighted defects'
    Jacobian without stacking them: scipy's norms of the stacked matrix, to the bit."""
    import scipy.sparse as sp

    from airbearing.analysis.shooting.sparse import stacked_column_norms, vstack_csc

    rng = np.random.default_rng(1)
    for _ in range(30):
        m, n = int(rng.integers(1, 400)), int(rng.integers(1, 60))
        density = rng.uniform(0, 0.9)
        A = sp.random(m, n, density=density, random_state=rng, format="csc")
        A = A * rng.lognormal(0, 5)
        B = sp.random(int(rng.integers(1, 30)), n, density=rng.uniform(0, 0.5),
                      random_state=rng, format="csc")  # fmt: skip
        want = np.sqrt(np.asarray(vstack_csc(A, B).power(2).sum(axis=0)).ravel())
        np.testing.assert_array_equal(stacked_column_norms(A, B), want)
