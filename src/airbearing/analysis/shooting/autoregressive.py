"""The one autoregressive noise model of a residual series: AR(p), AR(1) its p = 1 case.

A residual series ``x`` (noise units, in time order) is modelled as

    x_t = sum_l phi_l x_(t-l) + s u_t,    u_t ~ N(0, 1).

Two uses, one model (:class:`AR`):

- the coloured measurement noise of the shooting engine (:mod:`.measurement_noise`): an
  AR(1) per output group whose ``(phi, s)`` maximise the fit's Laplace marginal
  likelihood (``scipy.optimize``), applied on the log's own, possibly irregular, times
  (:meth:`AR.whitening_rows`: a sample ``d`` intervals after the previous one takes the
  coefficient ``phi^d``);
- the prewhitening of a sandwich covariance (:mod:`.errors`, the CMG inertia's): an
  AR(p) fitted by Yule-Walker with the order by AIC (:meth:`AR.yule_walker`,
  ``statsmodels.tsa.stattools``), applied on consecutive samples (:meth:`AR.whiten`,
  :meth:`AR.recolour_t`, ``scipy.signal.lfilter``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["AR", "MAX_CORRECTION_STEPS", "WHITE_SIGNIFICANCE"]

#: p-value of the likelihood-ratio test against white noise below which a Yule-Walker AR
#: model is kept (as the coloured-noise model's test, :data:`.measurement_noise.SIGNIFICANCE`).
WHITE_SIGNIFICANCE = 1e-3
#: Most steps of the fixed point that corrects residual autocovariances for the free
#: variables (:meth:`AR.yule_walker`).
MAX_CORRECTION_STEPS = 100


@dataclass(frozen=True)
class AR:
    """An AR(p) noise model (module doc).

    Attributes
    ----------
    phi : ndarray (p,)
        The coefficients per sample interval (empty: white noise).
    s : float
        The innovation's standard deviation, in the series' units.
    """

    phi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    s: float = 1.0

    @property
    def order(self) -> int:
        """``p``, the number of coefficients (0: white)."""
        return int(np.size(self.phi))

    @property
    def filter(self) -> np.ndarray:
        """``[1, -phi_1, ..., -phi_p]``: the whitening filter's numerator."""
        return np.r_[1.0, -np.asarray(self.phi, dtype=float)]

    @property
    def long_run_variance(self) -> float:
        """``s^2 / (1 - sum phi)^2``: the spectral density at frequency 0 (times 2 pi)."""
        return float(self.s**2 / (1.0 - float(np.sum(self.phi))) ** 2)

    def whiten(self, x: np.ndarray, axis: int = 0) -> np.ndarray:
        """The innovations ``Phi(L) x`` of consecutive samples (times ``s``: not rescaled)."""
        from scipy.signal import lfilter  # 1.4 s CPU to import (scipy.stats): only when used

        return lfilter(self.filter, [1.0], x, axis=axis)

    def recolour_t(self, X: np.ndarray) -> np.ndarray:
        """``Phi(L)^-T X``: regressors filtered backwards in time by the inverse filter, so
        that ``X' x = (Phi^-T X)' (Phi x)`` exactly (the prewhitened scores)."""
        from scipy.signal import lfilter  # 1.4 s CPU to import (scipy.stats): only when used

        return lfilter([1.0], self.filter, X[::-1], axis=0)[::-1]

    def whitening_rows(self, t: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The exact whitening of an AR(1) sampled at times ``t`` (s): a lower bidiagonal
        matrix given as ``(diagonal (n,), subdiagonal (n-1,))``.

        A sample ``d = max((t_i - t_(i-1)) / dt, 1)`` intervals after the previous one takes
        the coefficient ``a = phi^d`` and the innovation's standard deviation over ``d``
        steps, ``s sqrt((1 - a^2) / (1 - phi^2))``; the first sample its marginal one,
        ``s / sqrt(1 - phi^2)``.

        Parameters
        ----------
        t : ndarray (n,)
            s, the sample times in order.
        dt : float
            s, the interval ``phi`` refers to.

        Raises
        ------
        ValueError
            For an order above 1 (its exact whitening on irregular times is not this one).
        """
        if self.order > 1:
            raise ValueError(f"whitening on irregular times is an AR(1)'s; got order {self.order}")
        phi = float(self.phi[0]) if self.order else 0.0
        s = float(self.s)
        steps = np.maximum(np.diff(np.asarray(t, dtype=float)) / dt, 1.0)
        a = np.sign(phi) * np.abs(phi) ** steps if phi != 0.0 else np.zeros(steps.size)
        ratio = (1.0 - a**2) / (1.0 - phi**2) if phi != 0.0 else np.ones(steps.size)
        d = np.empty(steps.size + 1)
        d[0] = math.sqrt(1.0 - phi**2) / s
        d[1:] = 1.0 / (s * np.sqrt(ratio))
        return d, -a * d[1:]

    @classmethod
    def yule_walker(cls, series, maxlag: int, n_free: float = 0.0) -> AR:
        """The AR(p) of pooled residual series: Yule-Walker (Levinson-Durbin on the
        length-weighted autocovariances, ``statsmodels.tsa.stattools``), the order by AIC up
        to ``maxlag``, 0 (white) unless a likelihood-ratio test says the model beats white
        noise. Yule-Walker keeps the filter stable.

        A residual's autocovariances are biased low: each of the ``n_free`` free variables
        fitted to it (a window's initial state, smooth over the window) takes about one
        long-run variance ``lambda`` (the spectral density at frequency 0) out of the sum
        of its squares, so that every lag's sample autocovariance is short by about
        ``n_free lambda / n`` (the demeaning bias of a sample autocovariance, ``-lambda /
        n`` for one mean). The autocovariances are corrected by that amount at the long-run
        variance ``s^2 / (1 - sum phi)^2`` of the model fitted to the corrected ones (a
        fixed point, reached from no correction); the correction never exceeds the variance
        itself (a noise correlated over a window's length is not told from its initial
        state). On 10 s windows of a spin-down under white plus AR(1) gyro noise
        (correlated over 20 samples) the uncorrected model's long-run variance was about
        half the noise's.

        Parameters
        ----------
        series : iterable of ndarray
            1-D series (noise units); those no longer than ``2 maxlag`` or constant are
            left out.
        maxlag : int
            The longest order tried.
        n_free : float
            The number of free variables fitted to these series (0: raw series).

        Returns
        -------
        AR
            ``x_t = sum_l phi_l x_(t-l) + s u_t`` (order 0, ``s`` 1, when nothing is
            usable).

        Examples
        --------
        >>> import numpy as np
        >>> from scipy.signal import lfilter
        >>> x = lfilter([1.0], [1.0, -0.8], np.random.default_rng(0).standard_normal(4000))
        >>> model = AR.yule_walker([x], maxlag=10)
        >>> round(float(model.phi[0]), 1)
        0.8
        """
        from statsmodels.tsa.stattools import acovf  # 2.1 s CPU to import: only when fitted

        series = list(series)
        used = [x for x in series if x.size > 2 * maxlag and np.any(x != x[0])]
        if maxlag < 1 or not used:
            return cls()
        n = sum(x.size for x in used)
        g = sum(x.size * acovf(x, demean=False, fft=True, nlag=maxlag) for x in used) / n
        if g[0] <= 0:
            return cls()
        share = n_free / sum(x.size for x in series)  # free variables per sample
        phi, s2, lrv = _yule_walker_aic(g, n)
        for _ in range(MAX_CORRECTION_STEPS):
            if share <= 0:
                break
            step = min(share * lrv, g[0])
            phi, s2, new = _yule_walker_aic(g + step, n)
            if step >= g[0] or abs(new - lrv) <= 1e-3 * new:
                break
            lrv = new
        return cls(phi=phi, s=math.sqrt(s2))


def _yule_walker_aic(g: np.ndarray, n: int):
    """``(phi, innovation variance, long-run variance)`` of the AR model of autocovariances
    ``g`` (lags 0..p_max) whose order minimises AIC
    (``statsmodels.tsa.stattools.levinson_durbin``), taken only when it beats white noise in
    a likelihood-ratio test (``scipy.stats.chi2``, p below :data:`WHITE_SIGNIFICANCE`): AIC
    alone found orders of 11 and 23, coefficients summing to 0.05 and -0.01, in the nearly
    white residuals of the identify-platform tutorial (2400 samples per output), and moved
    its errors by 3 %."""
    from scipy import stats  # 1.2 s CPU to import: only when a model is fitted
    from statsmodels.tsa.stattools import levinson_durbin  # 2.1 s CPU, as above

    _, _, pacf, _, phi = levinson_durbin(g, nlags=g.size - 1, isacov=True)
    innov = g[0] * np.cumprod(np.r_[1.0, 1.0 - pacf[1:] ** 2])  # innovation variance per order
    loglik = -0.5 * n * np.log(np.maximum(innov, 1e-300))
    p = int(np.argmax(loglik - np.arange(innov.size)))  # AIC
    if p > 0 and stats.chi2.sf(2.0 * (loglik[p] - loglik[0]), p) >= WHITE_SIGNIFICANCE:
        p = 0
    coef = np.asarray(phi[1 : p + 1, p], dtype=float) if p > 0 else np.zeros(0)
    return coef, float(innov[p]), float(innov[p]) / (1.0 - float(coef.sum())) ** 2
