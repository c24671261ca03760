"""The search over the design family: per shape ``(zeta, r)`` the largest admissible
speed ``w``, shapes on a grid, then a compass search around the best."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from airbearing.design.tuning.screening import _INSIDE, _W_MIN, _Fast

__all__: list[str] = []

# the design family's box and the search grid on it (see the package docstring)
_ZETA_RANGE = (0.3, 3.0)
_RATIO_RANGE = (1e-4, 30.0)
_ZETA_GRID = (0.4, 0.7, 1.1, 1.8)
_RATIO_GRID = (1e-4, 3e-3, 0.1, 1.0)
_COMPASS = (0.2, math.log(10) / 2)  # first compass steps: ln zeta, ln r
_COMPASS_MIN = 0.05  # stop when the ln zeta step falls below this
# settling times this close to the shortest count as equally fast (package docstring)
_EQUALLY_FAST = 0.10
_SPEED_TOL = 0.02  # relative bracket of the largest admissible speed w
_BRACKET = 1.25  # first step of the bracket on w (squared at each further step)


@dataclass
class _Candidate:
    w: float
    zeta: float
    ratio: float
    gains: dict
    worst: dict

    @property
    def unsettled(self) -> int:
        """Corners of the box where the response does not settle within its longest run."""
        return self.worst.get("unsettled", 0)

    @property
    def settling(self) -> float:
        """The objective, s: the worst-case settling of the linear step or, when longer,
        of the rate-limited 180 deg slew, over the corners where it settles."""
        return self.worst.get("settled", 0.0)

    def key(self) -> tuple:
        """Smaller is faster: corners that never settle, then the settling time, then the
        larger bandwidth."""
        return (self.unsettled, round(self.settling, 9), -self.worst["wb"])


def _fastest_at(fast: _Fast, family, zeta, ratio, w0, w_hi) -> _Candidate | None:
    """The largest admissible speed of one shape: a bracket grown geometrically from
    ``w0`` (the best speed of the shapes before), then bisection on ``ln w``."""

    def judge(w):
        g = family(w, zeta, ratio)
        return g, fast.assess(g)

    lo = hi = best = None
    w, step = min(w0, w_hi), _BRACKET
    g, a = judge(w)
    if a.ok:
        lo, best = w, g
        while hi is None and lo < w_hi:
            w = min(lo * step, w_hi)
            g, a = judge(w)
            if a.ok:
                lo, best = w, g
            else:
                hi = w
            step *= step
        if hi is None:
            hi = lo  # admissible up to the fastest speed tried
    else:
        hi = w
        while lo is None:
            w = hi / step
            if w < _W_MIN:
                return None
            g, a = judge(w)
            if a.ok:
                lo, best = w, g
            else:
                hi = w
            step *= step
    while hi / lo > 1 + _SPEED_TOL:
        w = math.sqrt(lo * hi)
        g, a = judge(w)
        if a.ok:
            lo, best = w, g
        else:
            hi = w
    outside = len(fast.rest)
    final = fast.assess(best, every=True)  # every corner, and the objective: settling
    if not final.ok:
        if len(fast.rest) < outside:  # a corner outside the search's set failed: it joined
            return _fastest_at(fast, family, zeta, ratio, lo, w_hi)
        return None  # fails only once its responses run to the end: not this shape
    return _Candidate(lo, zeta, ratio, best, final.worst)


def _at_bandwidth(fast: _Fast, family, zeta, ratio, target, w_hi) -> _Candidate | None:
    """The shape at the smallest speed whose worst-case w_B reaches ``target`` (rad/s)."""
    target = target * (1 + _INSIDE["bandwidth"])
    lo, hi = _W_MIN, None
    w = 1.0
    for _ in range(40):
        if fast.bandwidth(family(w, zeta, ratio)) >= target:
            hi = w
            break
        lo = w
        w *= 2
        if w > w_hi:
            return None
    if hi is None:
        return None
    lo = max(lo, hi / 2**12)
    while hi / lo > 1 + _SPEED_TOL:
        w = math.sqrt(lo * hi)
        if fast.bandwidth(family(w, zeta, ratio)) >= target:
            hi = w
        else:
            lo = w
    g = family(hi, zeta, ratio)
    a = fast.assess(g, every=True)
    return _Candidate(hi, zeta, ratio, g, a.worst) if a.ok else None


def _search(fast: _Fast, family, w_hi, target, progress) -> tuple:
    """The best shape: a grid over (zeta, r), then a compass search around the best."""
    best: _Candidate | None = None
    tried: dict = {}
    w0 = 1 / (10 * fast.dt)

    def run(zeta, ratio):
        nonlocal best, w0
        key = (round(math.log(zeta), 6), round(math.log(ratio), 6))
        if key in tried:
            return tried[key]
        if target is None:
            c = _fastest_at(fast, family, zeta, ratio, w0, w_hi)
        else:
            c = _at_bandwidth(fast, family, zeta, ratio, target, w_hi)
        tried[key] = c
        if c is not None:
            w0 = c.w
            if best is None or c.key() < best.key():
                best = c
        return c

    total = len(_ZETA_GRID) * len(_RATIO_GRID)
    for i, zeta in enumerate(_ZETA_GRID):
        progress("searching damping and integral ratio", i * len(_RATIO_GRID), total)
        for ratio in _RATIO_GRID:
            run(zeta, ratio)
    if best is None:
        return None, len(tried)
    progress("refining the best shape", total, total)
    dz, dr = _COMPASS
    while dz >= _COMPASS_MIN:
        here = best
        for sz, sr in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            zeta = float(np.clip(here.zeta * math.exp(sz * dz), *_ZETA_RANGE))
            ratio = float(np.clip(here.ratio * math.exp(sr * dr), *_RATIO_RANGE))
            run(zeta, ratio)
        if best is here:
            dz, dr = dz / 2, dr / 2
    return _choose([c for c in tried.values() if c is not None]), len(tried)


def _choose(found: list) -> _Candidate:
    """The design to return among the shapes' fastest: the fewest corners where the
    response never settles, then settling times within ``_EQUALLY_FAST`` of the shortest
    count as equally fast, and among those the least worst-case overshoot wins, then the
    larger w_B."""
    fewest = min(c.unsettled for c in found)
    found = [c for c in found if c.unsettled == fewest]
    shortest = min(c.settling for c in found)
    fast_enough = [c for c in found if c.settling <= shortest * (1 + _EQUALLY_FAST)]
    return min(fast_enough, key=lambda c: (c.worst["overshoot"], -c.worst["wb"]))
