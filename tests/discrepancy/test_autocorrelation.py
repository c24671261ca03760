"""The search's autocorrelations, portmanteau test, HAC sum and AR filters in NumPy.

Reference: the library functions they replace (statsmodels, scipy.stats, scipy.signal) on
the same series; equal to round-off (1e-12: sums of a few thousand products, FFTs of other
lengths).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.signal import lfilter
from statsmodels.stats.diagnostic import acorr_ljungbox
from statsmodels.stats.sandwich_covariance import S_hac_simple
from statsmodels.tsa.stattools import acf as sm_acf
from statsmodels.tsa.stattools import acovf as sm_acovf
from statsmodels.tsa.stattools import levinson_durbin as sm_levinson_durbin

from airbearing.analysis.shooting.autocorrelation import (
    acf,
    acovf,
    chi2_sf,
    hac_bartlett,
    levinson_durbin,
    ljung_box_p,
)
from airbearing.analysis.shooting.autoregressive import AR


def _ar2(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return lfilter([1.0], [1.0, -0.6, 0.2], rng.standard_normal(n)) + 0.3


@pytest.mark.parametrize("n", [9, 257, 3000])
def test_autocorrelations_are_statsmodels(n):
    x = _ar2(n, n)
    lags = min(n // 2, 40)
    for fft in (True, False):
        assert np.allclose(
            acf(x, lags, fft=fft), sm_acf(x, nlags=lags, fft=fft), rtol=0, atol=1e-12
        )
    g = acovf(x, lags, demean=False, fft=True)
    ref = sm_acovf(x, demean=False, fft=True, nlag=lags)
    assert np.allclose(g, ref, rtol=1e-12, atol=0)
    pacf, phi = levinson_durbin(g, lags)
    _, _, pacf_ref, _, phi_ref = sm_levinson_durbin(g, nlags=lags, isacov=True)
    assert np.allclose(pacf, pacf_ref, rtol=0, atol=1e-12)
    assert np.allclose(phi, phi_ref, rtol=0, atol=1e-12)


def test_ljung_box_hac_and_chi2_are_the_libraries():
    for seed, h in ((1, 10), (2, 3)):
        x = _ar2(400, seed)
        ref = float(acorr_ljungbox(x, lags=[h], return_df=True)["lb_pvalue"].iloc[-1])
        assert ljung_box_p(x, h) == pytest.approx(ref, rel=1e-10, abs=1e-300)
    white = np.random.default_rng(3).standard_normal(400)
    ref = float(acorr_ljungbox(white, lags=[10], return_df=True)["lb_pvalue"].iloc[-1])
    assert ljung_box_p(white, 10) == pytest.approx(ref, rel=1e-10)
    X = np.column_stack([_ar2(500, 4), _ar2(500, 5)])
    for nlags in (None, 0, 7):
        assert np.allclose(hac_bartlett(X, nlags), S_hac_simple(X, nlags=nlags), rtol=1e-12)
    for x, df in ((0.3, 1), (9.5, 1), (40.0, 12), (0.0, 3)):
        assert chi2_sf(x, df) == pytest.approx(float(stats.chi2.sf(x, df)), rel=1e-12)


def test_ar_filters_are_lfilter():
    rng = np.random.default_rng(6)
    for phi in ([0.8], [0.5, -0.2, 0.1]):
        model = AR(phi=np.array(phi), s=1.0)
        for n in (1, 2, 60):
            X = rng.standard_normal((n, 3))
            ref = lfilter([1.0], model.filter, X[::-1], axis=0)[::-1]
            assert np.allclose(model.recolour_t(X), ref, rtol=0, atol=1e-12)
            ref = lfilter(model.filter, [1.0], X, axis=0)
            assert np.allclose(model.whiten(X), ref, rtol=0, atol=1e-12)
