"""The fast paths of airbearing.io.quality flag exactly what the per-row reference flags.

``assess`` computes the leave-one-out residuals of regular windows with one weight
vector per window shape (``_loo``, and ``_shape_residuals`` for all shapes at
once), the local scale only at the rows that need it
(``_window_median``), the first pass's scores of non-suspects as upper bounds, and
the quaternion signs from run heads (``_signs_along_parents``). The oracle is the
rule computed the slow way: one least-squares solve per row (``_loo_reference``),
pandas' rolling median over whole segments, every score exact, and plain pointer
doubling. On logs with glitches, gaps, irregular rows and both regular and jittered
sampling the two must give the same segments, the same outlier and unexplained rows,
the same columns and reasons, and scores and noise scales equal to rounding. The fast
paths live in airbearing.io.quality_outliers (the rule on one channel group): the oracle
patches them there, where ``assess``'s scorers look them up.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from test_log_quality import QUAT, RATES, mocap_yaw_log, tumble_log

from airbearing import quaternion as S
from airbearing import quaternion as quat
from airbearing.io import Log
from airbearing.io import local_fits as F
from airbearing.io import quality as Q
from airbearing.io import quality_outliers as QO

# ----------------------------------------------------------------------------
# the slow reference (the oracle)


def _median_by_pandas(values, lo, hi, rows, min_periods):
    """pandas' centred rolling median over each row's whole segment, at ``rows``."""
    out = np.empty((rows.size, values.shape[1]))
    for a, b in {(int(x), int(y)) for x, y in zip(lo, hi, strict=True)}:
        frame = pd.DataFrame(values[a:b])
        med = frame.rolling(2 * F.LOCAL + 1, center=True, min_periods=min_periods).median()
        at = (lo == a) & (hi == b)
        out[at] = med.to_numpy()[rows[at] - a]
    return out


def _signs_by_pointer_doubling(parent, rel):
    while np.any(parent != parent[parent]):
        rel = rel * rel[parent]
        parent = parent[parent]
    return rel * rel[parent]


def _shape_residuals_one_by_one(group, t, segments, k, p, scale, rows):
    good = np.ones(t.size, dtype=bool)
    return np.stack(
        [
            QO._normalised(group, t, segments, good, k, p, scale, rows, shape=a)[0]
            for a in range(2 * k + 1)
        ]
    )


def reference_quality(monkeypatch, log: Log) -> Q.LogQuality:
    """``assess`` with every fast path replaced by the slow one."""
    exact_call = Q._Scorer.__call__

    def always_exact(self, rows, good, exact=True):
        return exact_call(self, rows, good, exact=True)

    with monkeypatch.context() as m:
        m.setattr(QO, "_loo", F.loo_reference)
        m.setattr(QO, "_shape_residuals", _shape_residuals_one_by_one)
        m.setattr(QO, "_window_median", _median_by_pandas)
        m.setattr(S, "_signs_along_parents", _signs_by_pointer_doubling)
        m.setattr(Q._Scorer, "__call__", always_exact)
        return Q.assess(log, log.testbed)


def assert_same(fast: Q.LogQuality, slow: Q.LogQuality) -> None:
    assert fast.segments == slow.segments
    assert fast.irregular_rows == slow.irregular_rows
    assert fast.outlier_rows == slow.outlier_rows
    assert fast.unexplained_rows == slow.unexplained_rows
    assert fast.fits == slow.fits
    for f, s in zip(fast.outliers, slow.outliers, strict=True):
        assert (f.row, f.columns, f.reason) == (s.row, s.columns, s.reason)
        # both are the same least-squares prediction; they differ by the rounding of
        # the logged times and the per-row Gram solve (condition ~1e8 for p = 6):
        # relative 1e-7 leaves the 3-digit reasons and every threshold decision alone
        assert f.score == pytest.approx(s.score, rel=1e-7)
    assert fast.noise.keys() == slow.noise.keys()
    for c in fast.noise:
        assert fast.noise[c] == pytest.approx(slow.noise[c], rel=1e-7)


# ----------------------------------------------------------------------------
# logs with glitches, gaps and irregular rows


def glitched_tumble(seed: int, jitter: float, t0: float) -> tuple[pd.DataFrame, object]:
    """A tumble on a regular (jitter 0) or jittered grid starting at ``t0`` s, with gyro
    spikes, zeroed packets, a pair of consecutive glitches, a run of three, a quaternion
    in another frame, three gaps and two irregular (short) intervals."""
    df, tb = tumble_log(seed, n=2400, jitter=jitter)
    rng = np.random.default_rng(50 + seed)
    if jitter == 0.0:
        df["t"] = t0 + np.arange(len(df)) / tb.sensors.rate  # as a logger writes it
    else:
        df["t"] += t0
    rows = rng.choice(np.arange(30, 2370), 12, replace=False)
    for r in rows[:5]:
        df.loc[r, RATES[rng.integers(3)]] += rng.choice([0.01, 0.05, 0.3])
    for r in rows[5:8]:
        df.loc[r, RATES] = 0.0
    df.loc[rows[8] : rows[8] + 1, "wz"] += 0.05
    df.loc[rows[9] : rows[9] + 2, "wx"] += 0.05
    turn = quat.from_axis_angle([1, 0, 0], np.pi / 2)
    df.loc[rows[10], QUAT] = quat.qmul(turn, df.loc[rows[10], QUAT].to_numpy(float))
    df.loc[[0, len(df) - 1], RATES] = 0.0  # first and last sample artefacts
    t = df["t"].to_numpy().copy()
    t[800:] += 3.0  # gap
    t[1600:] += 7.5  # gap
    t[1200:] -= 0.7 / tb.sensors.rate  # an interval of 0.3 periods: irregular
    t[2000] = t[1999] + 0.2 / tb.sensors.rate  # early: irregular, then a gap to 2001
    df["t"] = t
    return df, tb


@pytest.mark.parametrize(
    ("seed", "jitter", "t0"),
    [(0, 0.0, 0.0), (1, 0.0, 1.0e5), (2, 0.2, 0.0), (3, 0.0, 3.7e3)],
    ids=["regular", "regular-late-start", "jittered", "regular-odd-start"],
)
@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_fast_and_reference_flag_the_same_rows(monkeypatch, seed, jitter, t0):
    df, tb = glitched_tumble(seed, jitter, t0)
    log = Log(df, "run.csv", tb)
    fast = log.quality
    slow = reference_quality(monkeypatch, log)
    assert_same(fast, slow)
    # the log is a hard case, not a clean one: glitches of every kind are found, and
    # the run of three and the values logged at shifted times are unexplained
    assert len(fast.outlier_rows) >= 8 and len(fast.unexplained_rows) >= 3
    assert 1200 in fast.irregular_rows and 2000 in fast.irregular_rows
    assert fast.segments[:3] == ((0, 800), (800, 1600), (1600, 2001))


def test_fast_and_reference_agree_on_mocap_yaw_with_glitches(monkeypatch):
    # an attitude-only dof-1 log on a regular grid: the yaw group (wrapped residuals)
    df, tb = mocap_yaw_log(seed=3)
    df.loc[1000:, "t"] += 20.0
    df.loc[[313, 1435], "yaw"] += np.radians(8.0)
    df.loc[1700, "yaw"] = 0.0
    log = Log(df, "run.csv", tb)
    assert_same(log.quality, reference_quality(monkeypatch, log))
    assert log.quality.outlier_rows == (313, 1435, 1700)


def test_fast_and_reference_agree_on_a_noise_free_simulation(monkeypatch):
    # the quiet-channel floor (running median of |second difference|) takes part here
    from airbearing.analysis.simulation import artefacts
    from airbearing.analysis.simulation.scenarios import free_oscillation
    from airbearing.io import load_testbed

    tb = load_testbed("seed004-platform")
    log = free_oscillation(
        tb, initial_rate=(0.05, -0.03, 0.2), q0=(0.99, 0.1, 0.0, 0.0), duration=60, seed=3
    ).log
    glitched, rows = artefacts.with_glitches(log, [100, 700], "rate_spike")
    assert_same(glitched.quality, reference_quality(monkeypatch, glitched))
    assert glitched.quality.outlier_rows == rows


def test_regular_windows_use_the_shape_weights_and_others_solve():
    # the fast path is taken exactly where the window is complete, clean and regular
    t = 100.0 + np.arange(40) * 0.05
    t[25:] += 0.01  # one longer interval between rows 24 and 25
    x = np.sin(t)[:, None]
    good = np.ones(40, bool)
    good[10] = False
    rows = np.arange(40)
    a, b = F.window_shape(40, 3, rows, None)
    fast = F.regular_span(t, good, rows, a, b, 3)
    # windows holding row 10 (excluded) or the interval 24-25 are not regular
    expected = np.ones(40, bool)
    expected[[r for r in rows if r - a[r] <= 10 <= r + b[r] and r != 10]] = False
    expected[[r for r in rows if r - a[r] <= 24 and r + b[r] >= 25]] = False
    assert fast.tolist() == expected.tolist()
    r_fast, h_fast, _ = F.loo(t, x, good, 3, 2, 0.05, rows)
    r_ref, h_ref, _ = F.loo_reference(t, x, good, 3, 2, 0.05, rows)
    # the same prediction (rounding of t ~ 1e-14 s relative to 0.05 s steps)
    np.testing.assert_allclose(r_fast, r_ref, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(h_fast, h_ref, rtol=1e-9)
    # interior h of the (3, 2) fit on a regular grid: module docstring, step 3 (0.50)
    assert h_fast[20] == pytest.approx(F.noise_gain(3, 2, 3), rel=1e-12)
    assert F.noise_gain(3, 2, 3) == pytest.approx(0.50, abs=0.005)


def test_window_median_is_pandas_rolling_median():
    rng = np.random.default_rng(4)
    v = rng.standard_normal((700, 2)) ** 2
    v[rng.uniform(size=v.shape) < 0.1] = np.nan
    v[300:340] = np.round(v[300:340], 1)  # ties
    lo = np.where(np.arange(700) < 400, 0, 400)
    hi = np.where(np.arange(700) < 400, 400, 700)
    rows = np.arange(700)
    for min_periods in (1, F.LOCAL):
        got = F.window_median(v, lo, hi, rows, min_periods)
        want = _median_by_pandas(v, lo, hi, rows, min_periods)
        assert np.array_equal(got, want, equal_nan=True)


def test_row_reductions_are_numpys_to_the_bit():
    """The outlier rule reduces the few columns of each row column by column (numpy's
    reduction along a short last axis is 10-30x slower): the same numbers as numpy's,
    NaN and signed zeros included, for every width the rule uses (1 to 7 columns)."""
    rng = np.random.default_rng(11)
    for c in range(1, 8):
        x = rng.standard_normal((500, c)) * 10.0 ** rng.integers(-8, 8, (500, c))
        x[rng.uniform(size=x.shape) < 0.02] = np.nan
        x[rng.uniform(size=x.shape) < 0.02] = -0.0
        b = x > 0.3
        assert np.array_equal(F.row_sum(x), np.sum(x, axis=1), equal_nan=True)
        assert np.array_equal(np.signbit(F.row_sum(x)), np.signbit(np.sum(x, axis=1)))
        assert np.array_equal(F.row_max(x), np.max(x, axis=1), equal_nan=True)
        assert np.array_equal(F.row_any(b), b.any(axis=1))
        assert np.array_equal(F.row_all(b), b.all(axis=1))
