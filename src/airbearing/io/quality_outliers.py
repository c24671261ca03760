"""The outlier rule on one channel group: local fits, noise scales, scores, masking.

The rule is told in :mod:`airbearing.io.quality`'s docstring (steps 2 to 7, "Inputs");
this module computes it for one :class:`_Group` of channels (the rates, the attitude, the
wheel speeds, an input: built by :mod:`airbearing.io.quality_channels`). ``_Scorer``
scores rows under the local fit chosen for each row's position (the step detector of
:mod:`airbearing.io.discontinuity` uses it too), :func:`find_outliers` masks the glitches
one at a time. The numerics of the fits are in :mod:`airbearing.io.local_fits`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from airbearing.io.discontinuity import (
    _CHI2_3_MEDIAN,
    _MAD_TO_SIGMA,
    CHI2_3_THRESHOLD,
    Z_THRESHOLD,
    poly_weights,
)
from airbearing.io.local_fits import LOCAL as _LOCAL
from airbearing.io.local_fits import REGULAR_ULPS as _REGULAR_ULPS
from airbearing.io.local_fits import loo as _loo_regular
from airbearing.io.local_fits import regular_span as _regular_span
from airbearing.io.local_fits import regular_weights as _regular_weights
from airbearing.io.local_fits import row_any, row_max, row_sum
from airbearing.io.local_fits import window_median as _window_median
from airbearing.io.local_fits import window_shape as _window_shape
from airbearing.io.quality_edges import edge_fits, gains

__all__ = ["ABSOLUTE_FLOOR", "FITS", "find_outliers"]

#: The local fits tried, ``(k, p)``: k samples each side, polynomial degree p.
FITS: tuple[tuple[int, int], ...] = ((3, 2), (4, 4), (5, 6))
_MAX_RUN = 2  # longest run of consecutive suspects that is an isolated glitch
#: rad or rad/s: no scale below this. A star tracker's 1 arcsec is 5e-6 rad and a
#: navigation-grade gyro has ~1e-6 rad/s of noise per sample at 20 Hz, so no real
#: sensor is this quiet; a noise-free simulated log is judged against it, not
#: against the local fits' own rounding and misfit.
ABSOLUTE_FLOOR = 1e-7
_MAX_PASSES = 200
_SCALE_ROWS = 2000  # rows spread over the log on which the noise scales are measured
_MIN_SCALE_SAMPLES = 8  # fewer residuals than this give no scale (the floor is used)
_RECOMPUTE = 3  # rows within this many k of a newly excluded sample are refitted
_ROUGH = 0.2  # noise-free channels: scale floor per unit median |second difference|


@dataclass
class _Group:
    name: str  # "rates", "attitude" or an input group ("gimbals", "sliders", "dipoles")
    columns: tuple[str, ...]  # log columns
    values: np.ndarray  # (n, c), prepared (signs continuous, yaw unwrapped)
    vector: bool  # True: one chi-square(3) test on the vector (quaternion)
    floor: np.ndarray  # (c,) or (1,) scale floor
    wrap: bool = False  # residual modulo 2 pi (yaw)
    sided: bool = False  # inputs: the best of the centred and one-sided fits (io.quality doc)
    # rows next to a command's switch: the best of the three fits there too (io.quality doc)
    switch_rows: np.ndarray | None = None


@lru_cache(maxsize=64)
def _offsets(k: int, a: int) -> np.ndarray:
    """Row offsets of the window with ``a`` left neighbours of ``2k``, in window order
    (``-a .. -1``, then ``1 .. 2k - a``), read-only (made once: ``np.r_`` costs ~50 us)."""
    out = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)]
    out.flags.writeable = False
    return out


def _loo(t, x, good, k, p, scale, rows, shape=None):
    """`local_fits.loo` (the parameters and returns are its own), with the windows that
    are complete (``2k`` neighbours, all good) but not regular (a jittered clock) fitted
    all at once (:func:`airbearing.io.discontinuity.poly_weights`) instead of one Gram
    solve per row: the same least-squares prediction, equal to its rounding."""
    a, b = _window_shape(t.size, k, rows, shape)
    full = (a + b) == 2 * k
    fast = _regular_span(t, good, rows, a, b, k) if full.any() else full
    cand = np.flatnonzero(full & ~fast)
    del b, full
    if len(cand) == 0:  # (without this call's arrays: a long log's peak memory)
        del a
        # the regular windows just found: not looked for twice (0.05 s per 10^6 rows)
        return _loo_regular(t, x, good, k, p, scale, rows, shape, fast=fast)
    del fast
    j = np.arange(2 * k)[None, :]
    ac = a[cand, None]
    nb = np.where(j < ac, rows[cand, None] - ac + j, rows[cand, None] + 1 + j - ac)
    complete = np.all(good[nb], axis=1)  # else: some neighbour excluded, the per-row solve
    cand, nb = cand[complete], nb[complete]
    if cand.size == 0:
        return _loo_regular(t, x, good, k, p, scale, rows, shape)
    r = np.full((rows.size, x.shape[1]), np.nan)
    h = np.full(rows.size, np.nan)
    rest = np.ones(rows.size, dtype=bool)
    rest[cand] = False
    if rest.any():
        r[rest], h[rest], _ = _loo_regular(t, x, good, k, p, scale, rows[rest], shape)
    at = rows[cand]
    w = poly_weights(t[nb] - t[at][:, None], p, np.zeros((at.size, 1)))[:, 0]
    r[cand] = x[at] - np.einsum("mj,mjc->mc", w, x[nb])
    h[cand] = np.sum(w * w, axis=1)
    return r, h, a


def _normalised(
    group: _Group,
    t: np.ndarray,
    segments,
    good: np.ndarray,
    k: int,
    p: int,
    scale: float,
    rows: np.ndarray,
    shape: int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Normalised residuals ``r / sqrt(1 + h)`` of ``rows`` (sorted), shape (len(rows), c),
    NaN where unchecked, and each row's window shape (left neighbours)."""
    out = np.full((rows.size, group.values.shape[1]), np.nan)
    shapes = np.full(rows.size, -1)
    bounds = np.asarray(segments, dtype=int).reshape(-1, 2)
    first = np.searchsorted(rows, bounds[:, 0])
    last = np.searchsorted(rows, bounds[:, 1])
    for i in np.flatnonzero((last > first) & (bounds[:, 1] - bounds[:, 0] >= 4)):
        (start, stop), lo, hi = bounds[i].tolist(), int(first[i]), int(last[i])
        r, h, a = _loo(
            t[start:stop],
            group.values[start:stop],
            good[start:stop],
            k,
            p,
            scale,
            rows[lo:hi] - start,
            shape,
        )
        if group.wrap:
            r = np.mod(r + np.pi, 2 * np.pi) - np.pi
        out[lo:hi] = r / np.sqrt(1.0 + h)[:, None]
        shapes[lo:hi] = a
    return out, shapes


def _scale(group: _Group, d: np.ndarray) -> np.ndarray:
    """Robust noise scale per channel (or one for a vector group) of normalised residuals."""
    d = d[np.all(np.isfinite(d), axis=1)]
    if d.shape[0] < _MIN_SCALE_SAMPLES:
        return np.full(group.floor.shape, np.nan)
    if group.vector:
        return np.array([np.sqrt(np.median(np.sum(d**2, axis=1)) / _CHI2_3_MEDIAN)])
    return _MAD_TO_SIGMA * np.median(np.abs(d - np.median(d, axis=0)), axis=0)


def _sample_rows(n: int) -> np.ndarray:
    """At most _SCALE_ROWS evenly spread rows: enough for a robust scale."""
    return np.unique(np.linspace(0, n - 1, min(n, _SCALE_ROWS)).astype(int))


@dataclass(frozen=True)
class _GroupResult:
    flagged: np.ndarray  # (n,) bool: outlier rows (isolated runs of 1-2)
    unexplained: np.ndarray  # (n,) bool: rows in longer runs of suspects
    score: np.ndarray  # (n,) final normalised score, noise scales (exact at suspects,
    # an upper bound elsewhere: see _Scorer.__call__)
    over: np.ndarray  # (n, c) per-channel exceedance at the final pass
    noise: np.ndarray  # robust noise scale per channel (one for a vector group)
    fit: tuple[int, int]  # (k, p) used


def _shape_residuals(
    group: _Group, t: np.ndarray, segments, k: int, p: int, scale: float, rows: np.ndarray
) -> np.ndarray:
    """Normalised residuals of ``rows`` (sorted) under every window shape, all samples good.

    ``out[a]`` is ``_normalised(group, t, segments, good, k, p, scale, rows, shape=a)[0]``
    for ``a = 0 .. 2k``, with the fast path of `local_fits.loo` (regular windows: the
    weights of their shape) taken for all shapes at once; the rows whose window is
    not regular have the least-squares weights of their own window, all rows of a
    shape at once (:func:`airbearing.io.discontinuity.poly_weights`: the same numbers as
    `local_fits.loo_reference` to its rounding).
    """
    n_shapes = 2 * k + 1
    out = np.full((n_shapes, rows.size, group.values.shape[1]), np.nan)
    if rows.size == 0:
        return out
    starts = np.array([a for a, _ in segments])
    stops = np.array([b for _, b in segments])
    seg = np.searchsorted(starts, rows, side="right") - 1
    lo, hi = starts[seg], stops[seg]
    shapes = np.arange(n_shapes)[:, None]
    fits = (rows - lo >= shapes) & (hi - 1 - rows >= 2 * k - shapes) & (hi - lo >= 4)
    # every shape's span [row - a, row - a + 2k] lies in [row - 2k, row + 2k]: the
    # intervals there once per row, each shape's 2k of them a slice (the same numbers)
    near = np.clip(rows[:, None] + np.arange(-2 * k, 2 * k + 1), 0, t.size - 1)
    dt_all = np.diff(t[near], axis=-1)  # (rows, 4k)
    big = np.maximum(np.abs(t[lo]), np.abs(t[hi - 1]))
    tol = _REGULAR_ULPS * np.spacing(big)
    regular = np.zeros(fits.shape, dtype=bool)
    for a in range(n_shapes):
        dt = dt_all[:, 2 * k - a : 4 * k - a]
        regular[a] = fits[a] & (np.max(dt, axis=-1) - np.min(dt, axis=-1) <= tol)
    x = group.values
    gathered = x[near.T]  # (4k + 1, rows, c): x at row + o, o = -2k .. 2k (clipped)
    for a in range(n_shapes):
        mine = regular[a]
        if mine.any():
            w = _regular_weights(k, p, a)
            offsets = _offsets(k, a)
            # as _loo's fast path, on every row (the same operations per element); the
            # rows outside `mine` (clipped neighbours) are dropped after
            with np.errstate(invalid="ignore", over="ignore"):
                pred = w[0] * gathered[2 * k + offsets[0]]
                for off, wj in zip(offsets[1:], w[1:], strict=True):
                    pred += wj * gathered[2 * k + off]
                r = (gathered[2 * k] - pred)[mine]
            if group.wrap:
                r = np.mod(r + np.pi, 2 * np.pi) - np.pi
            out[a, regular[a]] = r / np.sqrt(1.0 + float(w @ w))
        other = np.flatnonzero(fits[a] & ~regular[a])
        if other.size:  # jittered windows: the least-squares weights of each, all at once
            at = rows[other]
            offsets = _offsets(k, a)
            nb = at[:, None] + offsets
            w = poly_weights(t[nb] - t[at][:, None], p, np.zeros((at.size, 1)))[:, 0]
            r = x[at] - np.einsum("mj,mjc->mc", w, x[nb])
            if group.wrap:
                r = np.mod(r + np.pi, 2 * np.pi) - np.pi
            out[a, other] = r / np.sqrt(1.0 + np.sum(w * w, axis=1))[:, None]
    return out


def _shape_scales(group: _Group, t, segments, k: int, p: int, scale: float) -> np.ndarray:
    """Noise scale of the normalised residual for each window shape (0 .. 2k left neighbours).

    Edge samples are extrapolated; a fast motion leaves a larger misfit there than
    in the interior. Every shape is tried on the same spread of rows wherever it
    fits, so each shape's scale measures noise plus that shape's own misfit.
    """
    d_all = _shape_residuals(group, t, segments, k, p, scale, _sample_rows(t.size))
    scales = np.empty((2 * k + 1, group.floor.size))
    interior = None
    for a in [k, *range(0, k), *range(k + 1, 2 * k + 1)]:
        s = _scale(group, d_all[a])
        if a == k:
            interior = s
        if not np.all(np.isfinite(s)):
            s = interior if interior is not None and np.all(np.isfinite(interior)) else group.floor
        scales[a] = np.maximum(s, group.floor)
        if a != k:
            scales[a] = np.maximum(scales[a], scales[k])
    return scales


def _score(group: _Group, d: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row score (noise scales) and per-channel exceedance; NaN (unchecked) -> 0."""
    d = np.nan_to_num(d, nan=0.0)
    if group.vector:
        z2 = row_sum(d * d) / s[:, 0] ** 2
        over = np.repeat((z2 > CHI2_3_THRESHOLD)[:, None], d.shape[1], axis=1)
        return np.sqrt(z2), over
    z = np.abs(d) / s
    return row_max(z), z > Z_THRESHOLD


class _Scorer:
    """Normalised scores of rows under the local fit chosen for each row's position.

    Interior rows use the fit whose interior scale is smallest (io.quality docstring,
    step 3); the first and last ``k`` rows of a segment, which are extrapolated, use
    for each position the fit whose scale *at that position* is smallest, each
    shape's scale measured on the log itself (:func:`_shape_scales`), so that the
    misfit of extrapolating fast motion counts as part of that position's scale.
    """

    def __init__(self, group: _Group, t: np.ndarray, segments, scale: float) -> None:
        self.group, self.t, self.segments, self.scale = group, t, segments, scale
        self.scales = {f: _shape_scales(group, t, segments, *f, scale) for f in FITS}

        def key(f: tuple[int, int], a: int) -> float:
            # the smallest glitch this fit flags at this shape, in units of the noise:
            # scale x sqrt(1 + h) (the raw residual's spread), summed over channels
            s = self.scales[f][a]
            return float(np.sum(np.log(s)) + s.size * 0.5 * np.log1p(gains(*f)[a]))

        self.fit = min(FITS, key=lambda f: key(f, f[0]))
        n = t.size
        self.from_start = np.zeros(n, dtype=int)
        self.from_end = np.zeros(n, dtype=int)
        for start, stop in segments:
            self.from_start[start:stop] = np.arange(stop - start)
            self.from_end[start:stop] = np.arange(stop - start)[::-1]
        self.edge: dict[tuple[int, int], tuple[int, int]] = {}
        for side in (0, 1):
            for e in range(max(k for k, _ in FITS)):

                def shape(f: tuple[int, int], side: int = side, e: int = e) -> int:
                    k = f[0]
                    return k if e >= k else (e if side == 0 else 2 * k - e)

                best = min(FITS, key=lambda f, shape=shape: key(f, shape(f)))
                if best != self.fit:
                    self.edge[(side, e)] = best
        self._edge_depth = 1 + max((e for _, e in self.edge), default=-1)
        self._prepare_local()

    def _prepare_local(self) -> None:
        """What the local factor (:meth:`local_at`) of any row is computed from.

        Noise or motion that is rougher in one stretch of a log than overall (a
        manoeuvre with the commands changing at every sample, vibration while a
        motor runs) would otherwise be judged against the quieter overall scale. The
        local scale is a running median over ``2 * _LOCAL + 1`` samples of the
        segment; one glitch, and the few neighbours its fit pulls, cannot move a
        median of 51 samples much.
        """
        g = self.group
        n = self.t.size
        k, p = self.fit
        rows = np.arange(n)
        d, shapes = _normalised(g, self.t, self.segments, np.ones(n, bool), k, p, self.scale, rows)
        self._all_rows = (d, shapes)  # the first pass (nothing excluded yet) scores these
        # its (score, over) with exact=False, kept for the second ask (the step detector
        # asks first, the outlier search second)
        self._first_pass = None
        if g.vector:
            self._rough_sq = row_sum(d**2)[:, None] / _CHI2_3_MEDIAN
        else:
            self._rough_sq = (_MAD_TO_SIGMA * d) ** 2
        # A channel without noise (its scale at the physical floor: a simulation)
        # cannot tell a glitch from a kink (a torque switched between samples, a rate
        # limit reached) by statistics: its scale is never below _ROUGH x the running
        # median of |second difference|, the motion's own sample-to-sample change of
        # slope. Any real sensor noise is far above it, so it acts on noise-free logs only.
        quiet = self.noise <= g.floor * (1 + 1e-9)
        quiet &= g.floor <= ABSOLUTE_FLOOR * (1 + 1e-9)
        self._quiet = quiet
        self._step = None
        if quiet.any():
            d2 = np.zeros(g.values.shape)
            for start, stop in self.segments:
                if stop - start >= 3:
                    d2[start + 1 : stop - 1] = np.diff(g.values[start:stop], 2, axis=0)
            self._step = np.linalg.norm(d2, axis=1, keepdims=True) if g.vector else np.abs(d2)
        self._seg_lo = np.zeros(n, dtype=int)
        self._seg_hi = np.zeros(n, dtype=int)
        for start, stop in self.segments:
            self._seg_lo[start:stop], self._seg_hi[start:stop] = start, stop
        self._local = np.ones(self._rough_sq.shape)
        self._known = np.zeros(n, dtype=bool)

    def local_at(self, rows: np.ndarray) -> np.ndarray:
        """Per row and channel, how much rougher the log is locally than overall (>= 1).

        Computed for the rows asked (and kept): the running medians of
        :meth:`_prepare_local` at those rows (`local_fits.window_median`, the numbers of
        pandas' centred rolling median).
        """
        need = np.unique(rows[~self._known[rows]])
        if need.size:
            lo, hi = self._seg_lo[need], self._seg_hi[need]
            local = np.sqrt(_window_median(self._rough_sq, lo, hi, need, _LOCAL))
            ratio = local / self.noise[None, :]
            factor = np.where(np.isfinite(ratio), np.maximum(ratio, 1.0), 1.0)
            if self._step is not None:
                rough = _ROUGH * _window_median(self._step, lo, hi, need, 1)
                floor = np.maximum(factor, rough / self.noise[None, :])
                factor = np.where(self._quiet[None, :], floor, factor)
            self._local[need] = factor
            self._known[need] = True
        return self._local[rows]

    @property
    def noise(self) -> np.ndarray:
        return self.scales[self.fit][self.fit[0]]

    def _sided(self, rows, good, d, scale, fits=None):
        """Per row and channel, the fit (centred, all-left, all-right) that explains the
        sample best, in its own scale (io.quality doc, "Inputs").

        ``fits`` (default: the group's own fit only): on each side, the first of them (in
        order of degree) that explains that side's next sample (scored by the same
        one-sided fit, which leaves the tested row out) is that side's fit; where none
        does, the one that explains the row best. A glitch cannot choose its own fit.
        """
        g, t, segs, sc = self.group, self.t, self.segments, self.scale
        z = np.abs(d) / scale
        z = np.where(np.isfinite(z), z, np.inf)
        fits = fits or (self.fit,)
        n = t.size
        for right in (True, False):  # all neighbours after, all before
            chosen = np.zeros(rows.size, dtype=bool)
            side_d = np.full(d.shape, np.nan)
            side_s = np.ones(d.shape)
            side_z = np.full(d.shape, np.inf)
            for k, p in fits:
                a = 0 if right else 2 * k
                d_a, _ = _normalised(g, t, segs, good, k, p, sc, rows, shape=a)
                # no one-sided fit (too near the segment's end): not judged (io.quality doc)
                room = self.from_end[rows] if right else self.from_start[rows]
                d_a[room < 2 * k] = 0.0
                s_a = np.broadcast_to(self.scales[(k, p)][a], d_a.shape)
                z_a = np.abs(d_a) / s_a
                z_a = np.where(np.isfinite(z_a), z_a, np.inf)
                if len(fits) > 1:
                    nxt = rows + (1 if right else -1)
                    inside = (room > 2 * k) & (nxt >= 0) & (nxt < n)
                    d_n, _ = _normalised(
                        g, t, segs, good, k, p, sc, np.clip(nxt, 0, n - 1), shape=a
                    )
                    fine = inside & np.all(np.abs(d_n) / s_a <= Z_THRESHOLD, axis=1)
                else:
                    fine = np.ones(rows.size, dtype=bool)
                take = (fine & ~chosen)[:, None] | (~chosen[:, None] & (z_a < side_z))
                side_d, side_s, side_z = (
                    np.where(take, x_a, x)
                    for x_a, x in ((d_a, side_d), (s_a, side_s), (z_a, side_z))
                )
                chosen |= fine
            better = side_z < z
            d, scale, z = (
                np.where(better, x_a, x) for x_a, x in ((side_d, d), (side_s, scale), (side_z, z))
            )
        return d, scale

    def _at_shape(self, kf, pf, a, rows, good, fixed: bool) -> np.ndarray:
        """Normalised residuals of ``rows`` (sorted) by the fit ``(kf, pf)`` with ``a``
        left neighbours, NaN where that window does not fit in the row's segment.

        Windows that are regular with every neighbour good take the regular weights
        (as `local_fits.loo`'s fast path, all segments at once); the others are those
        of :func:`_normalised`, with the window of shape ``a`` (``fixed``: NaN where a
        neighbour is excluded) or the row's own sliding window (excluded neighbours
        left out)."""
        g, t = self.group, self.t
        out = np.full((rows.size, g.values.shape[1]), np.nan)
        if rows.size == 0:
            return out
        lo, hi = self._seg_lo[rows], self._seg_hi[rows]
        fits = (rows - a >= lo) & (rows + 2 * kf - a < hi)
        span = np.clip(rows[:, None] - a + np.arange(2 * kf + 1), 0, t.size - 1)
        dt = np.diff(t[span], axis=1)
        big = np.maximum(np.abs(t[lo]), np.abs(t[hi - 1]))
        fast = fits & (np.max(dt, axis=1) - np.min(dt, axis=1) <= _REGULAR_ULPS * np.spacing(big))
        offsets = _offsets(kf, a)
        nb = np.clip(rows[:, None] + offsets, 0, t.size - 1)
        fast &= np.all(good[nb], axis=1)
        if fast.any():
            w = _regular_weights(kf, pf, a)
            x, at, nb_f = g.values, rows[fast], nb[fast]
            pred = w[0] * x[nb_f[:, 0]]  # as _loo's fast path
            for j in range(1, w.size):
                pred += w[j] * x[nb_f[:, j]]
            r = x[at] - pred
            if g.wrap:
                r = np.mod(r + np.pi, 2 * np.pi) - np.pi
            out[fast] = r / np.sqrt(1.0 + float(w @ w))
        slow = fits & ~fast
        if slow.any():
            out[slow], _ = _normalised(
                g, t, self.segments, good, kf, pf, self.scale, rows[slow], a if fixed else None
            )
        return out

    def __call__(
        self, rows: np.ndarray, good: np.ndarray, exact: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Scores (noise scales) and per-channel exceedances of ``rows`` (sorted) when
        the fits use only the ``good`` samples.

        ``exact=False``: the exceedances are the same, and so are the scores of the
        rows that exceed; other rows' scores are upper bounds (their local factor,
        >= 1, is only computed where it could decide an exceedance).
        """
        g, t, segs, sc = self.group, self.t, self.segments, self.scale
        k, p = self.fit
        first_pass = rows.size == t.size and good.all()  # rows sorted: all of them
        if first_pass and not exact and self._first_pass is not None:
            kept, self._first_pass = self._first_pass, None  # asked for twice, not more
            return kept
        if first_pass and self._all_rows is not None:
            d, shapes = self._all_rows
        else:
            d, shapes = _normalised(g, t, segs, good, k, p, sc, rows)
        d = d.copy()
        scale = self.scales[self.fit][np.clip(shapes, 0, 2 * k)]
        # rows at a segment's first or last few positions may take another fit
        if g.sided:  # inputs: the fit per position (the best of three fits decides below)
            edge = np.ones(d.shape)
            edge_rows = np.flatnonzero(
                np.minimum(self.from_start[rows], self.from_end[rows]) < self._edge_depth
            )
            from_start = self.from_start[rows[edge_rows]]
            from_end = self.from_end[rows[edge_rows]]
            for (side, e), (kf, pf) in self.edge.items():
                at = (from_start if side == 0 else from_end) == e
                at &= (from_end if side == 0 else from_start) >= kf
                if not at.any():
                    continue
                at = edge_rows[at]
                d_f, shapes_f = _normalised(g, t, segs, good, kf, pf, sc, rows[at])
                d[at], scale[at] = d_f, self.scales[(kf, pf)][np.clip(shapes_f, 0, 2 * kf)]
        else:  # measurements: the fit per row, with the edge's own roughness
            d, scale, edge = edge_fits(self, rows, good, d, scale, FITS)
        if g.sided:
            d, scale = self._sided(rows, good, d, scale)
        elif g.switch_rows is not None:
            at = np.flatnonzero(g.switch_rows[rows])
            if at.size:
                # the motion changes its character at a switch (a rate limit reached
                # or left): every fit's one-sided form, the higher degrees follow it
                d_s, s_s = self._sided(rows[at], good, d[at], scale[at], FITS)
                # a row rescored by another fit there: that fit's scale, no edge factor
                edge[at] = np.where((d_s == d[at]) & (s_s == scale[at]), edge[at], 1.0)
                d[at], scale[at] = d_s, s_s
        if exact:
            return _score(g, d, scale * np.maximum(self.local_at(rows), edge))
        score, over = _score(g, d, scale)  # local factor 1: an upper bound of each score
        maybe = row_any(over)
        if maybe.any():
            factor = np.maximum(self.local_at(rows[maybe]), edge[maybe])
            score[maybe], over[maybe] = _score(g, d[maybe], scale[maybe] * factor)
        if first_pass and self._all_rows is not None:
            self._first_pass = (score.copy(), over.copy())
            self._all_rows = None  # its residuals are not needed again
        return score, over


def _best_explanation(
    scorer: _Scorer, i: int, suspect: np.ndarray, excluded: np.ndarray, seg_id, k: int
) -> tuple[int, ...]:
    """The rows near suspect ``i`` whose exclusion best explains its neighbourhood.

    A glitch pulls the fits of its neighbours; next to a segment's end, or when two
    consecutive samples are hit, a neighbour's residual can score higher than the
    glitch's own. Candidates are each suspect within ``k`` rows of ``i``, ``i`` and its
    two neighbours, and the two pairs of consecutive rows containing ``i``; the one
    taken minimises ``sum(score^2)`` of the remaining rows within ``2k`` plus the
    threshold squared for each row it leaves out (a glitch explains itself only if
    leaving it out removes more than an outlier's worth of misfit).
    """
    n = excluded.size
    window = np.arange(max(i - 2 * k, 0), min(i + 2 * k + 1, n))
    window = window[(seg_id[window] == seg_id[i]) & ~excluded[window]]
    near = [int(c) for c in window if abs(int(c) - i) <= k and suspect[c]]
    candidates = {(c,) for c in [*near, i - 1, i, i + 1]} | {(i - 1, i), (i, i + 1)}
    cost = CHI2_3_THRESHOLD if scorer.group.vector else Z_THRESHOLD**2
    best: tuple[int, ...] = (i,)
    best_metric = np.inf
    for cand in sorted(candidates, key=lambda c: (len(c), abs(c[0] - i))):
        if any(c < 0 or c >= n or seg_id[c] != seg_id[i] or excluded[c] for c in cand):
            continue
        good = ~excluded
        good[list(cand)] = False
        rows = window[good[window]]
        score = scorer(rows, good)[0]
        metric = float(np.sum(score**2)) + cost * len(cand)
        if metric < best_metric - 1e-9:
            best, best_metric = cand, metric
    return best


def find_outliers(
    group: _Group, t: np.ndarray, segments, scale: float, scorer: _Scorer | None = None
) -> _GroupResult:
    """Run the rule (io.quality doc) on one channel group (``scorer``: the group's,
    already built on the same segments)."""
    n = t.size
    scorer = scorer if scorer is not None else _Scorer(group, t, segments, scale)
    k = max(f[0] for f in FITS)
    seg_id = np.zeros(n, dtype=int)
    for i, (start, stop) in enumerate(segments):
        seg_id[start:stop] = i
    excluded = np.zeros(n, dtype=bool)
    # scores of rows that are not suspects are never used below (only the suspects' are
    # compared, and _best_explanation scores its windows exactly): upper bounds suffice
    score, over = scorer(np.arange(n), ~excluded, exact=False)
    for _ in range(_MAX_PASSES):
        suspect = row_any(over) & ~excluded
        if not suspect.any():
            break
        # only the largest suspect within k samples (same segment) is taken this pass
        take = []
        for i in np.flatnonzero(suspect):
            near = np.arange(max(i - k, 0), min(i + k + 1, n))
            near = near[(seg_id[near] == seg_id[i]) & suspect[near]]
            if score[i] >= np.max(score[near]):
                take.extend(_best_explanation(scorer, i, suspect, excluded, seg_id, k))
        excluded[take] = True
        # the fits that used a newly excluded sample change: recompute around them
        near_mask = np.zeros(n, dtype=bool)
        for i in take:
            near_mask[max(i - _RECOMPUTE * k, 0) : i + _RECOMPUTE * k + 1] = True
        again = np.flatnonzero(near_mask)
        score[again], over[again] = scorer(again, ~excluded, exact=False)
    suspect = excluded & row_any(over)
    flagged = np.zeros(n, dtype=bool)
    unexplained = np.zeros(n, dtype=bool)
    bad = np.flatnonzero(suspect)
    if bad.size:
        breaks = np.flatnonzero((np.diff(bad) != 1) | (np.diff(seg_id[bad]) != 0)) + 1
        for run in np.split(bad, breaks):
            (flagged if run.size <= _MAX_RUN else unexplained)[run] = True
    return _GroupResult(flagged, unexplained, score, over, scorer.noise, scorer.fit)
