"""What the engine keeps of a log through a whole search: one copy of the samples, and the
per-row bookkeeping in the narrowest integers (structural checks, not sizes).

- Reading a log hands the free pages of Arrow's memory pool back (an hour of 50 Hz
  three-axis samples left ~90 MB of them resident through the whole search).
- The replay's data keep the log they were given when it was read or made with the very
  testbed replayed (validated against it already), not a second, validated copy of its
  samples (and no pandas table made of its arrays).
- The log lets go of the sign-continuous quaternions its quality checks shared once they
  are done.
- A shooting problem's group, component and sample index of every residual row are 8 and
  32 bit integers (one entry per residual row: 10^6 on an hour of samples).
- The windows' arrays are views of the data vector their problems read, and the problems
  of one WindowSet share it and their per-row indices (the same numbers to the bit).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest
from rigs import spinning_seed004_50hz

from airbearing.analysis.discrepancy.replay import model_for, prepare, problem_for
from airbearing.analysis.shooting.logs import make_windows, noise_floor, replay_data
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


def test_the_log_keeps_no_signed_quaternions_once_assessed(tmp_path):
    from airbearing.io.motion import no_motion, signed_quaternions
    from airbearing.quaternion import continuous_signs

    tb, path = _written(tmp_path)
    log = read_log(path, tb)
    no_motion(log, tb)  # (the search's check of a still log, before the replay's data)
    assert "_signed_quaternions" in log.__dict__
    segments = log.quality.segments
    assert "_signed_quaternions" not in log.__dict__
    # asked again: the same numbers
    want = continuous_signs(log.quaternions(), segments)
    np.testing.assert_array_equal(signed_quaternions(log, segments), want)


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


def _rotor_datas():
    from rigs import ROTOR

    from airbearing.analysis.simulation.scenarios import spindown

    return ROTOR, [replay_data(ROTOR, spindown(ROTOR, duration=20.0, seed=3).log)]


@pytest.mark.parametrize("rig", ["platform", "rotor"])
@pytest.mark.parametrize("linked", [True, False])
def test_the_problems_of_one_windowset_share_its_data_vector(rig, linked):
    """The windows' arrays are views of the data vector the compiled functions read, the
    same numbers as a vector made from those arrays; the problems of the windows (with
    and without a sensor lag) share it and their per-row indices; a problem given other
    noise levels writes them in its own copy."""
    if rig == "platform":
        tb, log = spinning_seed004_50hz(2.0)
        datas = [replay_data(tb, Log(log.data, log.source, tb))]
    else:
        tb, datas = _rotor_datas()
    windows = make_windows(datas, window_s=0.5 if rig == "platform" else 2.0, linked=linked)
    floor = noise_floor(datas)
    pb = problem_for(model_for(tb, {}), datas, windows, floor)
    other = {"sensor_lag": 0.0} if rig == "platform" else {"viscous_friction": 0.0}
    lag = problem_for(model_for(tb, other), datas, windows, floor)
    assert pb._data is windows.data and lag._data is windows.data
    for name in ("x0", "u", "dt", "weight", "rate", "quat", "yaw"):
        a = getattr(windows, name)
        assert a is None or np.shares_memory(a, windows.data), name
        if a is not None:  # (a write would change every problem's data behind its back)
            with pytest.raises(ValueError, match="read-only"):
                a[(0,) * a.ndim] = 1.0
    alone = problem_for(model_for(tb, {}), datas, replace(windows, data=None), floor)
    assert alone._data is not windows.data
    np.testing.assert_array_equal(alone._data, windows.data)  # to the bit
    # windows whose arrays are not all views of their vector: a vector of their own
    other_weight = replace(windows, weight=windows.weight.copy())
    assert problem_for(model_for(tb, {}), datas, other_weight, floor)._data is not windows.data
    for name in ("group", "component", "sample", "usable", "primary"):
        assert getattr(lag, name) is getattr(pb, name)
        assert not getattr(pb, name).flags.writeable
    before = windows.data.copy()
    lag.set_noise(2 * lag.sigma_rate, 3 * lag.sigma_att)
    assert lag._data is not windows.data
    np.testing.assert_array_equal(windows.data, before)
    r = pb.residual(np.zeros((pb.n_delta, windows.n)), pb.model.p0)
    d = np.zeros((pb.n_delta, windows.n))
    np.testing.assert_array_equal(r, alone.residual(d, pb.model.p0))
