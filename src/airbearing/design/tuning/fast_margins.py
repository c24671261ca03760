"""Margins of a SISO loop from its frequency response on a grid, refined where the
response moves fast: the search's copy of :func:`airbearing.design.margins.loop_margins`."""

from __future__ import annotations

import math

import numpy as np

__all__: list[str] = []

# a crossing where, between grid points, the phase turns more than _TURN (rad) or the
# magnitude changes by more than _STEEP (in ln |L|) is refined
_TURN = 0.35
_STEEP = 0.1
_SUBGRID = 65  # points of each refinement (two levels at most)
_SQRT_HALF = 1 / math.sqrt(2)


def _siso_margins(w, L, stable: bool, exact) -> dict:
    """Margins of a SISO loop from its response ``L`` on the grid ``w`` (rad/s), as
    :func:`~airbearing.design.margins.loop_margins` defines them.

    Crossings are interpolated (log magnitude and phase, linear in ln w) on the grid.
    Where the response turns or falls fast between two grid points (a lightly damped
    mode), they are found again on finer grids of ``exact(frequencies) -> L``, and so are
    the pairs of crossings a resonance hides between two grid points (next to a local
    extreme of the response close to the line it would cross).
    """
    lw = np.log(w)

    def logmag(v):
        return np.log(np.maximum(np.abs(v), 1e-300))

    def off_axis(v):  # angle from the negative real axis, rad
        return np.angle(-v)

    def smooth(a, b) -> bool:
        return abs(np.angle(b / a)) < _TURN and abs(logmag(b) - logmag(a)) < _STEEP

    def changes(fs):
        return np.nonzero(np.sign(fs[:-1]) * np.sign(fs[1:]) < 0)[0]

    def brackets(f, near) -> list:
        """``(a, b, x0, x1)``: the response and ln w at the ends of every interval where
        ``f(L)`` changes sign, refined where the response moves fast."""
        fv = f(L)
        at = changes(fv)
        todo = [(L[i], L[i + 1], lw[i], lw[i + 1]) for i in at]
        flagged = set(at.tolist()) | {i + 1 for i in at.tolist()}
        a_ = np.abs(fv)
        for i in np.nonzero((a_[1:-1] <= a_[:-2]) & (a_[1:-1] <= a_[2:]) & (a_[1:-1] < near))[0]:
            if i + 1 in flagged or i in flagged:
                continue  # a crossing beside it on the grid already
            if smooth(L[i], L[i + 1]) and smooth(L[i + 1], L[i + 2]):
                continue  # too little movement to cross and come back between the points
            xs = np.linspace(lw[i], lw[i + 2], 2 * _SUBGRID - 1)
            ys = exact(np.exp(xs))
            todo += [(ys[k], ys[k + 1], xs[k], xs[k + 1]) for k in changes(f(ys))]
        out = []
        for a, b, x0, x1 in todo:
            for _ in range(2):
                if smooth(a, b):
                    break
                xs = np.linspace(x0, x1, _SUBGRID)
                ys = exact(np.exp(xs))
                k = changes(f(ys))
                if not k.size:
                    break
                k = int(k[0])
                a, b, x0, x1 = ys[k], ys[k + 1], xs[k], xs[k + 1]
            out.append((a, b, x0, x1))
        return out

    pms, wcs = [], []
    for a, b, x0, x1 in brackets(logmag, math.log(2)):
        if np.sign(logmag(a)) == np.sign(logmag(b)):
            continue
        f = logmag(a) / (logmag(a) - logmag(b))
        ph = np.angle(a) + f * np.angle(b / a)
        pm = math.degrees((ph + math.pi) % (2 * math.pi))
        pms.append(pm - 360 if pm > 180 else pm)
        wcs.append(math.exp(x0 + f * (x1 - x0)))
    gms = []
    for a, b, _, _ in brackets(off_axis, _TURN):
        pa, pb = off_axis(a), off_axis(b)
        if abs(pa) > math.pi / 2 or abs(pb) > math.pi / 2 or np.sign(pa) == np.sign(pb):
            continue  # across the positive real axis, not the negative
        # on the negative real axis the phase of -L crosses 0; log |L| is interpolated with
        # it (smooth in ln w where Re and Im, near a resonance, are not)
        f = pa / (pa - pb)
        gms.append(math.exp(-(logmag(a) + f * (logmag(b) - logmag(a)))))
    up = [g for g in gms if g > 1]
    gm = 20 * math.log10(min(up)) if up else math.inf
    if not pms:
        pm = math.inf
    else:
        pm = min(abs(x) for x in pms) if stable else min(pms)
    S = np.abs(1 / (1 + L))
    ms = float(S.max())
    # the |S| peak lies between grid points: a parabola through the three points around a
    # smooth peak, finer exact grids around a resonance's
    peaks = np.nonzero((S[1:-1] >= S[:-2]) & (S[1:-1] >= S[2:]) & (S[1:-1] > 0.8 * ms))[0] + 1
    for i in peaks:
        if smooth(L[i - 1], L[i]) and smooth(L[i], L[i + 1]):
            curve = S[i - 1] - 2 * S[i] + S[i + 1]
            if curve < 0:
                ms = max(ms, float(S[i] - (S[i - 1] - S[i + 1]) ** 2 / (8 * curve)))
            continue
        x0, x1 = lw[i - 1], lw[i + 1]
        for _ in range(2):
            xs = np.linspace(x0, x1, _SUBGRID)
            sub = np.abs(1 / (1 + exact(np.exp(xs))))
            k = int(np.argmax(sub))
            ms = max(ms, float(sub[k]))
            x0, x1 = xs[max(k - 1, 0)], xs[min(k + 1, _SUBGRID - 1)]
    wb = None
    below = S < _SQRT_HALF
    if below[0]:
        idx = np.nonzero(~below)[0]
        if idx.size:
            i = idx[0] - 1
            f = (_SQRT_HALF - S[i]) / (S[i + 1] - S[i])
            wb = math.exp(lw[i] + f * (lw[i + 1] - lw[i]))
    return {"pm": pm, "gm": gm, "ms": ms, "wb": wb}
