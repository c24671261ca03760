"""The frequency side of the margins: the logarithmic grid a loop is evaluated on
(:func:`frequency_grid`), its frequency response from the state-space matrices, batched
over the frequencies (:func:`frequency_response`, on ``z = exp(j w T)`` for a discrete
loop), and the natural frequencies and damping of poles (:func:`pole_damping`)."""

from __future__ import annotations

import math

import numpy as np

from airbearing.design import _control as ct

__all__ = ["N_GRID", "frequency_grid", "frequency_response", "pole_damping"]

#: Points of the logarithmic frequency grid.
N_GRID = 3000


def frequency_grid(sys: ct.StateSpace, n: int = N_GRID) -> np.ndarray:
    """Logarithmic grid, rad/s: two decades below the slowest pole or zero to Nyquist
    (discrete) or two decades above the fastest (continuous)."""
    poles = np.asarray(sys.poles())
    if sys.isdtime(strict=True):
        with np.errstate(divide="ignore"):
            s = np.log(poles[np.abs(poles) > 0].astype(complex)) / sys.dt
        mags = np.abs(s)
        hi = math.pi / sys.dt * (1 - 1e-9)
    else:
        mags = np.abs(poles)
        hi = None
    mags = mags[(mags > 1e-12) & np.isfinite(mags)]
    lo = max(mags.min() / 100, 1e-9) if mags.size else 1e-3
    if hi is None:
        hi = mags.max() * 100 if mags.size else 1e3
    lo = min(lo, hi / 1e4)
    return np.logspace(math.log10(lo), math.log10(hi), n)


def frequency_response(sys: ct.StateSpace, omega) -> np.ndarray:
    """Frequency response ``C (xI - A)^-1 B + D`` at ``x = jw`` or ``exp(jwT)``.

    Batched linear solves over the frequencies (python-control's ``horner`` without
    slycot loops in Python).

    Parameters
    ----------
    sys : control.StateSpace
        Continuous or discrete (sample time ``T``, s).
    omega : array_like (n,)
        rad/s.

    Returns
    -------
    ndarray
        Complex; SISO shape ``(n,)``, MIMO ``(p, m, n)``.
    """
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
    x = np.exp(1j * w * sys.dt) if sys.isdtime(strict=True) else 1j * w
    n = A.shape[0]
    if n:
        M = x[:, None, None] * np.eye(n) - A[None]
        X = np.linalg.solve(M, np.broadcast_to(B, (w.size,) + B.shape))
        G = np.einsum("ij,kjl->kil", C, X) + D[None]
    else:
        G = np.broadcast_to(D[None].astype(complex), (w.size,) + D.shape)
    G = np.moveaxis(G, 0, -1)
    return G[0, 0] if sys.issiso() else G


def pole_damping(poles, dt: float | None):
    """Natural frequencies (rad/s) and damping ratios of poles (z-plane when ``dt``)."""
    poles = np.asarray(poles, dtype=complex)
    if dt:
        with np.errstate(all="ignore"):
            s = np.log(poles) / dt
    else:
        s = poles
    wn = np.abs(s)
    with np.errstate(invalid="ignore", divide="ignore"):
        zeta = np.where(wn > 0, -s.real / wn, -np.sign(s.real + 0.0) + (s.real == 0))
    # a pole at z = 0 (a sample of computation delay) is infinitely fast: damping 1, not NaN
    zeta = np.where(np.isinf(wn), 1.0, zeta)
    return wn, zeta
