"""The outlier rule at a segment's first rows, where its fits extrapolate.

A dof-1 gyro log's ``yaw`` is the loop's estimate (FORMATS.md; seed 001 eqs. 3 and 21):
the integral of the low-passed gyro rate, the filter started at 0 with the log. A slew
that starts moving at once then begins with the filter's start-up transient (a decay of
``1 - f_g = 0.75`` per sample, 3.5 samples), which the one-sided degree-4 fit of row 0
misses by ~1.1e-4 rad where the log's own shape-0 misfit is ~1e-5 rad: with the yaw's
noise scale of ~2e-6 rad, row 0 scored 6-8 noise scales and was flagged in 4 of 30
noisy 3 s slews (9 of 20 at 5 s). The next rows inwards, extrapolated by the same fit
from windows without row 0, show the same misfit (io.quality doc, step 4): that is the
scale of row 0, and the fit that follows the transient is the one taken there.

Oracle: the simulator (a clean log has no glitch anywhere) and injected spikes.
"""

from __future__ import annotations

import pytest
from scipy import stats

from airbearing.analysis.simulation.scenarios import slew
from airbearing.io.log import Log
from airbearing.io.quality import Z_THRESHOLD, assess
from airbearing.io.testbed import Sensors, load_testbed

#: rad/s, white: the public CMG examples' gyro noise (as tests/hidden_cases.py)
GYRO_NOISE = 5e-4
#: s: 60 rows at 20 Hz; the slew accelerates from the first row on
DURATION = 3.0
SEEDS = range(20)


@pytest.fixture(scope="module")
def noisy_cmg():
    tb = load_testbed("cmg-yaw")  # seed 001's gyro low-pass f_g = 0.25 kept
    return tb.replace(
        sensors=Sensors(rate=tb.sensors.rate, gyro_noise=GYRO_NOISE, lowpass=tb.sensors.lowpass)
    )


@pytest.fixture(scope="module")
def slews(noisy_cmg):
    return {seed: slew(noisy_cmg, duration=DURATION, seed=seed).log for seed in SEEDS}


@pytest.mark.slow  # over 3 s of an idle core: CI runs it once (.ci/run)
def test_a_clean_slew_that_starts_at_once_has_no_outlier(noisy_cmg, slews):
    # every sample is the simulator's: any flag is false. The rule's own rate: a
    # two-sided Gaussian tail at Z_THRESHOLD per sample and channel (wz, yaw, d1..d4)
    per_test = 2 * stats.norm.sf(Z_THRESHOLD)
    tests = sum(len(log.data) for log in slews.values()) * 6
    expected = tests * per_test
    assert expected < 1e-4  # so even one flag in these logs is not chance
    # (before: row 0's yaw flagged at 6.2-7.0 noise scales in seeds 6, 11 and 12)
    flagged = {s: assess(log, noisy_cmg).outlier_rows for s, log in slews.items()}
    assert {s: rows for s, rows in flagged.items() if rows} == {}


def spiked(log, row, column, size):
    df = log.data.copy()
    df.loc[row, column] += size
    return Log(df, "glitched.csv", log.testbed)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("where", ["first", "last"])
def test_a_gyro_spike_in_an_end_row_is_still_found(noisy_cmg, slews, seed, where):
    # 30 gyro sigmas: an end row's one-sided (3, 2) fit flags above
    # 6 x sqrt(1 + 3.2) = 12.3 sigmas times its scale there, which is up to ~1.6 at this
    # 3 s log's last row (mid-manoeuvre); measured before and after the edge factor:
    # 15-20 sigmas are the least found, the same rows
    log = slews[seed]
    row = 0 if where == "first" else len(log.data) - 1
    q = assess(spiked(log, row, "wz", 30 * GYRO_NOISE), noisy_cmg)
    assert q.outlier_rows == (row,)
    assert q.outliers[0].columns == ("wz",)


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_a_yaw_spike_in_row_0_is_still_found(noisy_cmg, slews, seed):
    # The yaw's noise (the integrated gyro) is ~2e-6 rad per sample, and row 0 takes the
    # degree-6 fit that follows the start-up transient: its extrapolation's gain
    # sqrt(1 + 161) = 12.7 and its scale there ~1.3 flag above ~100 noise scales; a
    # spike of 400 (~1e-3 rad, 0.05 deg) is found at its row, not at a neighbour
    log = slews[seed]
    sigma = assess(log, noisy_cmg).noise["yaw"]
    q = assess(spiked(log, 0, "yaw", 400 * sigma), noisy_cmg)
    assert q.outlier_rows == (0,)
    assert q.outliers[0].columns == ("yaw",)


def test_the_edge_tests_quantile_is_scipy_stats_chi2():
    """The edge tests' thresholds come from scipy.special (scipy.stats is not loaded by
    the log check); the same numbers as ``scipy.stats.chi2.isf``, fractional dof too."""
    from airbearing.io.quality_edges import chi2_isf

    for level, dof in [(5e-4, 1.0), (5e-4, 3.0), (5e-4, 7.37), (1e-3, 22.5)]:
        assert chi2_isf(level, dof) == pytest.approx(stats.chi2.isf(level, dof), rel=1e-12)
