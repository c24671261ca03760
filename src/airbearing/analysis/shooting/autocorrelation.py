"""Autocorrelations, Levinson-Durbin, the Ljung-Box test and the Newey-West sum, in NumPy.

They give the numbers of ``statsmodels.tsa.stattools`` ``acovf``, ``acf`` and
``levinson_durbin``, ``statsmodels.stats.diagnostic.acorr_ljungbox`` and
``statsmodels.stats.sandwich_covariance.S_hac_simple`` (sums over ``n``, Bartlett
weights), checked equal to them to 1e-12 in
``tests/discrepancy/test_autocorrelation.py``. A deliberate exception to "use the
library", as :mod:`airbearing.analysis.filters` is for ``scipy.signal``: every discrepancy
search takes honest errors and an adequacy test, and importing statsmodels (which pulls
``scipy.stats`` in) cost 1.25 s of CPU in each new process, more than the rest of the
horizon. The chi-square tail comes from ``scipy.special`` (what ``scipy.stats.chi2.sf``
evaluates).
"""

from __future__ import annotations

import numpy as np
from scipy import special

__all__ = ["acf", "acovf", "chi2_sf", "hac_bartlett", "levinson_durbin", "ljung_box_p"]


def acovf(x: np.ndarray, nlag: int, demean: bool = True, fft: bool = True) -> np.ndarray:
    """Autocovariance of ``x`` at lags ``0..nlag``, sums over ``n`` (``statsmodels``'
    ``acovf(x, demean=demean, fft=fft, nlag=nlag)``)."""
    x = np.asarray(x, dtype=float)
    n = x.size
    xo = x - x.mean() if demean else x
    if fft:
        m = 1 << int(2 * n - 1).bit_length()  # zero padding: no circular wrap
        f = np.fft.rfft(xo, m)
        acov = np.fft.irfft(f * np.conj(f), m)[:n] / n
    else:
        acov = np.correlate(xo, xo, "full")[n - 1 :] / n
    return acov[: nlag + 1]


def levinson_durbin(g: np.ndarray, nlags: int):
    """``(pacf, phi)`` of the autocovariances ``g`` (lags ``0..nlags``) by the
    Levinson-Durbin recursion: the partial autocorrelations (``pacf[0] = 1``) and
    ``phi[1:p + 1, p]`` the AR(p) coefficients of every order ``p`` (``statsmodels``'
    ``levinson_durbin(g, nlags, isacov=True)``'s third and fifth outputs)."""
    g = np.asarray(g, dtype=float)
    phi = np.zeros((nlags + 1, nlags + 1))
    sig = np.zeros(nlags + 1)
    phi[1, 1] = g[1] / g[0]
    sig[1] = g[0] - phi[1, 1] * g[1]
    for k in range(2, nlags + 1):
        phi[k, k] = (g[k] - np.dot(phi[1:k, k - 1], g[1:k][::-1])) / sig[k - 1]
        for j in range(1, k):
            phi[j, k] = phi[j, k - 1] - phi[k, k] * phi[k - j, k - 1]
        sig[k] = sig[k - 1] * (1 - phi[k, k] ** 2)
    pacf = np.diag(phi).copy()
    pacf[0] = 1.0
    return pacf, phi


def acf(x: np.ndarray, nlags: int, fft: bool = True) -> np.ndarray:
    """Autocorrelation of ``x`` at lags ``0..nlags`` (mean removed, sums over ``n``).

    Parameters
    ----------
    x : ndarray (n,)
    nlags : int
        Largest lag (at most ``n - 1``).
    fft : bool
        By the FFT (long series) or by direct sums.

    Returns
    -------
    ndarray (nlags + 1,)
        ``statsmodels.tsa.stattools.acf(x, nlags=nlags, fft=fft)``.
    """
    acov = acovf(x, nlags, demean=True, fft=fft)
    return acov / acov[0]


def chi2_sf(x, df):
    """The chi-square law's upper tail ``P(X > x)`` with ``df`` degrees of freedom
    (``scipy.stats.chi2.sf``)."""
    return special.chdtrc(df, x)


def ljung_box_p(x: np.ndarray, h: int) -> float:
    """The Ljung-Box test's p-value of ``x`` white over lags ``1..h``
    (``acorr_ljungbox(x, lags=[h])["lb_pvalue"]``)."""
    n = np.asarray(x).size
    r = acf(x, h, fft=False)[1:]
    q = n * (n + 2) * float(np.sum(r**2 / (n - np.arange(1, h + 1))))
    return float(chi2_sf(q, h))


def hac_bartlett(x: np.ndarray, nlags: int | None = None) -> np.ndarray:
    """The Newey-West inner sum ``sum_j w_j (G_j + G_j^T)`` of the rows of ``x`` with
    Bartlett weights ``w_j = 1 - j / (nlags + 1)`` (``S_hac_simple``; ``nlags`` default
    ``floor(4 (n / 100)^(2/9))``).

    Parameters
    ----------
    x : ndarray (n,) or (n, k)
    nlags : int, optional

    Returns
    -------
    ndarray (k, k)
    """
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    n = x.shape[0]
    if nlags is None:
        nlags = int(np.floor(4 * (n / 100.0) ** (2.0 / 9.0)))
    w = 1 - np.arange(nlags + 1) / (nlags + 1.0)
    S = w[0] * np.dot(x.T, x)
    for lag in range(1, nlags + 1):
        s = np.dot(x[lag:].T, x[:-lag])
        S += w[lag] * (s + s.T)
    return S
