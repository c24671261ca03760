"""Small signal tools in numpy: the one differentiator of logged signals (a least-squares
local polynomial, :func:`local_poly` on the logged, possibly irregular, times with its noise
propagation; :func:`savgol` its uniform-grid form) and a Welch power spectral density (the
discrepancy search, the balancing metrics, identification's attitude-only rates).

They give the numbers of ``scipy.signal.savgol_filter(..., mode="interp")`` and
``scipy.signal.welch`` (defaults: periodic Hann window, half overlap, constant detrend,
one-sided density), checked against scipy in ``tests/discrepancy/test_discrepancy_search.py``.
Importing ``scipy.signal`` costs about 1 s of CPU (it pulls ``scipy.stats`` in), a
sixth of a whole ``airbearing discrepancy`` run once the search is screened.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["local_poly", "savgol", "savgol_weights", "welch"]


def savgol_weights(window: int, order: int, deriv: int, delta: float, z: float) -> np.ndarray:
    """Weights giving the ``deriv``-th derivative at offset ``z`` (samples from the window's
    centre) of the least-squares polynomial of ``order`` through ``window`` samples."""
    half = window // 2
    V = np.vander(np.arange(-half, half + 1, dtype=float), order + 1, increasing=True)
    basis = np.zeros(order + 1)
    for j in range(deriv, order + 1):
        basis[j] = math.factorial(j) / math.factorial(j - deriv) * z ** (j - deriv)
    return basis @ np.linalg.pinv(V) / delta**deriv


def savgol(x: np.ndarray, window: int, order: int, deriv: int = 0, delta: float = 1.0):
    """Savitzky-Golay smoothing or derivative along axis 0 (``mode="interp"`` edges).

    Parameters
    ----------
    x : ndarray (n, ...)
        Samples on a uniform grid of spacing ``delta``; ``n >= window``.
    window : int
        Odd number of samples of each local fit.
    order : int
        Polynomial order (< window).
    deriv : int
        Derivative order (0: smoothed values).
    delta : float
        Sample spacing (units of x per unit of the derivative's variable, e.g. s).

    Returns
    -------
    ndarray, like ``x``
    """
    x = np.asarray(x, dtype=float)
    n, half = x.shape[0], window // 2
    out = np.empty_like(x)
    w = savgol_weights(window, order, deriv, delta, 0.0)
    # interior: a correlation with the centre weights
    acc = np.zeros((n - 2 * half, *x.shape[1:]))
    for k in range(window):
        acc += w[k] * x[k : n - 2 * half + k]
    out[half : n - half] = acc
    # edges: the polynomial of the first (last) window evaluated off-centre
    for i in range(half):
        out[i] = savgol_weights(window, order, deriv, delta, i - half) @ x[:window]
        out[n - half + i] = savgol_weights(window, order, deriv, delta, i + 1) @ x[n - window :]
    return out


def local_poly(t, y, weight, half: int, degree: int, *, noise: bool = False):
    """Value and slope of a weighted least-squares local polynomial at every sample.

    Around each sample a polynomial of ``degree`` in time is fitted to the
    ``2 half + 1`` samples about it at their logged times (the window shifted inwards at
    the ends), each sample weighted by ``weight`` (0: an outlier row left out); on a
    uniform grid with unit weights it is the Savitzky-Golay filter (:func:`savgol_weights`).

    Parameters
    ----------
    t : ndarray (N,)
        s, sample times in increasing order.
    y : ndarray (N, k)
        Samples (any unit).
    weight : ndarray (N,)
        Non-negative weight of each sample (0 or 1 for a mask).
    half : int
        Samples each side of the centre (the window is at most the series).
    degree : int
        Polynomial degree (lowered to the window's samples minus one).
    noise : bool
        Also return the slope's noise propagation.

    Returns
    -------
    value : ndarray (N, k)
        The fitted polynomial at each sample (units of ``y``).
    slope : ndarray (N, k)
        Its time derivative there (units of ``y`` per s).
    slope_std : ndarray (N,)
        Only with ``noise``: 1/s, the slope's standard deviation per unit of a white
        noise on ``y`` at unit weight (``sqrt(e1' A^-1 V' W^2 V A^-1 e1) / h``); 0 with
        degree 0.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.cumsum(np.r_[0.0, np.full(20, 0.1) + 0.01 * np.sin(np.arange(20))])
    >>> _, slope = local_poly(t, (t**2)[:, None], np.ones(t.size), 4, 3)
    >>> bool(np.allclose(slope[:, 0], 2 * t))
    True
    """
    t = np.asarray(t, dtype=float)
    n = len(t)
    width = min(2 * half + 1, n)
    deg = min(degree, width - 1)
    h = float(np.median(np.diff(t))) if n > 1 else 1.0
    centre = np.arange(n)
    start = np.clip(centre - half, 0, n - width)
    idx = start[:, None] + np.arange(width)[None, :]
    tau = (t[idx] - t[:, None]) / h  # (N, W): times in median intervals, for conditioning
    V = tau[..., None] ** np.arange(deg + 1)  # (N, W, d+1)
    Wt = np.asarray(weight, dtype=float)[idx][..., None]
    A = np.einsum("nwi,nwj->nij", V * Wt, V)
    rhs = np.einsum("nwi,nwk->nik", V * Wt, y[idx])
    c = np.linalg.solve(A, rhs)  # (N, d+1, k)
    slope = c[:, 1, :] / h if deg >= 1 else np.zeros_like(c[:, 0, :])
    if not noise:
        return c[:, 0, :], slope
    if deg < 1:
        return c[:, 0, :], slope, np.zeros(n)
    # the slope is g' y with g = W V A^-1 e1 / h: its variance per unit white noise is g'g
    e1 = np.zeros((n, deg + 1, 1))
    e1[:, 1, 0] = 1.0
    a1 = np.linalg.solve(A, e1)  # (N, d+1, 1): A is symmetric
    g = np.einsum("nwi,nio->nw", V * Wt, a1)
    return c[:, 0, :], slope, np.sqrt(np.sum(g**2, axis=1)) / h


def welch(x: np.ndarray, fs: float, nperseg: int):
    """One-sided power spectral density of the columns of ``x`` by Welch's method.

    Periodic Hann window of ``nperseg`` samples, ``nperseg // 2`` overlap, each segment's
    mean removed, segments averaged (``scipy.signal.welch`` defaults).

    Returns
    -------
    f : ndarray (nperseg // 2 + 1,)
        Hz.
    pxx : ndarray (nperseg // 2 + 1, ...)
        Units of x squared per Hz.
    """
    x = np.asarray(x, dtype=float)
    step = nperseg - nperseg // 2
    count = (x.shape[0] - nperseg // 2) // step
    win = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(nperseg) / nperseg)
    win = win.reshape(-1, *([1] * (x.ndim - 1)))
    scale = 1.0 / (fs * float(np.sum(win**2)))
    acc = 0.0
    for s in range(count):
        seg = x[s * step : s * step + nperseg]
        X = np.fft.rfft((seg - seg.mean(axis=0)) * win, axis=0)
        acc = acc + np.abs(X) ** 2
    pxx = acc * scale / max(count, 1)
    last = -1 if nperseg % 2 == 0 else None
    pxx[1:last] *= 2.0
    return np.fft.rfftfreq(nperseg, 1.0 / fs), pxx
