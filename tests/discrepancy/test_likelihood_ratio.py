"""The likelihood ratio that decides whether a candidate may be named (discrepancy/trial.py).

Oracle: Wilks' theorem. For a candidate that is not in the data (a regressor of pure noise)
and acts on the noisy rows (a gyro bias on the gyro's), the ratio of two nested least-squares
fits follows chi-square with one degree of freedom, whatever share of the other residuals
carries no noise (an output group weighted by a floor, such as a noise-free attitude beside a
gyro). Checked by a Kolmogorov-Smirnov test against ``scipy.stats.chi2`` on 4,000 draws of a
fixed seed (p > 1e-3; the doubled ratio the quiet rows gave before, p < 1e-6). A regressor
that also acts on the quiet rows, where the weights overstate the noise, gives a smaller
ratio: the test is conservative there, never liberal.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from airbearing.analysis.discrepancy.trial import lr_of, noise_count

DRAWS, ROWS = 4000, 400


def _null_ratios(quiet_share: float, sigma: float, everywhere=False, seed=7) -> np.ndarray:
    """Ratios of a pure-noise regressor on residuals of which ``quiet_share`` carry no
    noise and the rest noise of ``sigma`` (the weights say 1); the regressor acts on the
    noisy rows only, or ``everywhere``."""
    rng = np.random.default_rng(seed)
    noisy = np.arange(ROWS) >= quiet_share * ROWS
    y = rng.normal(0.0, sigma, (DRAWS, ROWS)) * noisy
    x = rng.normal(size=(DRAWS, ROWS)) * (True if everywhere else noisy)
    rss0 = np.einsum("ij,ij->i", y, y)
    rss1 = rss0 - np.einsum("ij,ij->i", x, y) ** 2 / np.einsum("ij,ij->i", x, x)
    return np.array(
        [
            lr_of(SimpleNamespace(n_res=ROWS, n_free=0, rss=float(r0)), float(r1))
            for r0, r1 in zip(rss0, rss1, strict=True)
        ]
    )


@pytest.mark.parametrize(
    "quiet_share, sigma",
    [(0.0, 1.0), (0.5, 1.0), (0.0, 3.0)],
    ids=["all-noisy", "half-quiet", "noise-over-the-weights"],
)
def test_a_candidate_not_in_the_data_gives_a_chi_square_ratio(quiet_share, sigma):
    # sigma 3: the noise is larger than the weights say, its scale estimated from the fit
    # (the usual n ln(RSS0/RSS1)); sigma 1 with half the rows quiet: s2 = 0.5, the weights
    # are the noise (on the noisy half they are exact)
    lr = _null_ratios(quiet_share, sigma)
    assert stats.kstest(lr, stats.chi2(1).cdf).pvalue > 1e-3


def test_quiet_rows_do_not_double_the_ratio():
    # counted as noise, the quiet half would double every ratio: Wilks rejects that
    lr = _null_ratios(0.5, 1.0)
    assert stats.kstest(2.0 * lr, stats.chi2(1).cdf).pvalue < 1e-6


def test_a_candidate_also_acting_on_quiet_rows_is_judged_conservatively():
    # the 95 % quantile is exceeded in at most 5 % of draws (3 binomial std of slack)
    lr = _null_ratios(0.5, 1.0, everywhere=True)
    slack = 3 * np.sqrt(0.05 * 0.95 / DRAWS)
    assert np.mean(lr > stats.chi2(1).ppf(0.95)) <= 0.05 + slack


def test_noise_count_is_the_rows_unless_the_residuals_are_below_the_weights():
    fit = SimpleNamespace(n_res=1000, n_free=10, rss=1980.0)
    assert noise_count(fit) == 1000
    fit = SimpleNamespace(n_res=1000, n_free=10, rss=495.0)
    assert noise_count(fit) == pytest.approx(500.0)
    assert lr_of(fit, 0.0) == np.inf
