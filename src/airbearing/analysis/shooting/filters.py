"""Two small signal tools in numpy: a Savitzky-Golay derivative of logged signals and a
Welch power spectral density (the discrepancy search, the balancing metrics).

They give the numbers of ``scipy.signal.savgol_filter(..., mode="interp")`` and
``scipy.signal.welch`` (defaults: periodic Hann window, half overlap, constant detrend,
one-sided density), checked against scipy in ``tests/discrepancy/test_discrepancy_search.py``.
Importing ``scipy.signal`` costs about 1 s of CPU (it pulls ``scipy.stats`` in), a
sixth of a whole ``airbearing discrepancy`` run once the search is screened.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["savgol", "savgol_weights", "welch"]


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
