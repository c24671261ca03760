"""The outlier rule at a segment's ends: each edge row's fit and its edge factor.

A row within ``k`` samples of its segment's start or end is extrapolated by its local
fit, and a motion may change fastest exactly there (a logged estimate's filter starting
with the log), which the log-wide scale of the window shape does not see.
:func:`edge_fits` gives each such row the fit of :data:`~airbearing.io.quality_outliers.FITS`
that flags the smallest glitch there, with the scale times :func:`edge_factor`: the root
mean square of the normalised residuals of the ``2k`` rows inwards (windows without the
row), where they fail a test of white noise at :data:`EDGE_LEVEL`. The rule is told in
:mod:`airbearing.io.quality`'s docstring (step 3); the scorer (``_Scorer`` of
:mod:`airbearing.io.quality_outliers`) provides the residuals and the scales.

The tests' chi-square quantiles are scipy's (:func:`chi2_isf`).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from airbearing.io.local_fits import noise_gain, residual_correlation

__all__ = ["EDGE_LEVEL", "chi2_isf", "edge_factor", "edge_fits"]

#: Level of the test that an edge's inward rows are rougher than the log-wide scale
#: (:func:`edge_factor`): a false alarm only lowers the sensitivity at that edge.
EDGE_LEVEL = 1e-3


@lru_cache(maxsize=8)
def gains(k: int, p: int) -> np.ndarray:
    """`local_fits.noise_gain` of the fit ``(k, p)`` for every window shape ``0 .. 2k``."""
    return np.array([noise_gain(k, p, a) for a in range(2 * k + 1)])


@lru_cache(maxsize=256)
def chi2_isf(level: float, dof: float) -> float:
    """The chi-square quantile ``scipy.stats.chi2.isf(level, dof)``, by the function it
    calls (``scipy.special.chdtri``): importing scipy.stats costs 1-3 s of CPU, and
    identify's equation-error path loads no scipy.stats."""
    from scipy.special import chdtri  # 0.3-0.6 s to import: only when a test needs it

    return float(chdtri(dof, level))


def edge_fits(scorer, rows, good, d, scale, candidates):
    """The fit, scale and edge factor of the rows near a segment's ends (step 3).

    Each row within the largest ``k`` of a segment's end takes the fit of ``candidates``
    (:data:`~airbearing.io.quality_outliers.FITS`) that flags the smallest glitch
    *there*: the smallest product over channels of its window shape's scale, its edge
    factor (:func:`edge_factor`) and ``sqrt(1 + h)``. Nothing of it depends on the
    row's own sample (the scales are the log's, the edge factor comes from windows
    without the row), so a glitch cannot choose the fit that hides it. Returns ``d,
    scale, edge`` of all ``rows``.
    """
    edge = np.ones(d.shape)
    kmax = max(k for k, _ in candidates)
    near = np.flatnonzero(np.minimum(scorer.from_start[rows], scorer.from_end[rows]) < kmax)
    if near.size == 0:
        return d, scale, edge
    r = rows[near]
    length = scorer.from_start[r] + scorer.from_end[r] + 1
    best = np.full(near.size, np.inf)
    d_near, s_near, e_near = d[near].copy(), scale[near].copy(), edge[near].copy()
    for kf, pf in candidates:
        fits = length >= 2 * kf + 1  # a full window of 2k neighbours
        if not fits.any():
            continue
        rf = r[fits]
        fs, fe = scorer.from_start[rf], scorer.from_end[rf]
        sh_f = np.where(fs < kf, fs, np.where(fe < kf, 2 * kf - fe, kf))
        d_f = np.empty((rf.size, d.shape[1]))
        for a in np.unique(sh_f):
            d_f[sh_f == a] = scorer._at_shape(kf, pf, int(a), rf[sh_f == a], good, False)
        s_f = scorer.scales[(kf, pf)][np.clip(sh_f, 0, 2 * kf)]
        full = np.full(sh_f.size, kf)
        e_f = edge_factor(scorer, r[fits], good, full, np.full(sh_f.size, pf), sh_f, d_f)
        gain = gains(kf, pf)[sh_f]
        key = np.sum(np.log(s_f * e_f), axis=1) + d.shape[1] * 0.5 * np.log1p(gain)
        key = np.where(np.all(np.isfinite(d_f), axis=1), key, np.inf)
        at = np.flatnonzero(fits)
        take = key < best[at]
        at = at[take]
        best[at] = key[take]
        d_near[at], s_near[at], e_near[at] = d_f[take], s_f[take], e_f[take]
    d[near], scale[near], edge[near] = d_near, s_near, e_near
    return d, scale, edge


def edge_factor(scorer, rows, good, fit_k, fit_p, shapes, d) -> np.ndarray:
    """Per row and channel, how much rougher the motion is at an extrapolated edge
    position than the log-wide scale of its window shape says (>= 1; io.quality doc,
    step 4).

    A row ``e`` samples from its segment's start has ``e < k`` left neighbours: its
    fit extrapolates, and a motion that changes fast where the log begins (a filter's
    start-up transient in a logged estimate) leaves a misfit there that the shape's
    scale, measured over the whole log, does not contain. The same fit with the same
    shape predicts the ``2k`` rows inwards from windows that do not contain the row
    (rows ``e + 1 + j`` with ``e`` left neighbours start after it), so a glitch in
    the row cannot raise its own scale. They are tested against white noise at
    :data:`EDGE_LEVEL` (half for each statistic): their sum, which a misfit makes
    of one sign (normal, with the variance ``1' C 1`` of the residuals' white-noise
    correlation ``C``), and their sum of squares (the scaled chi-square with the
    same two moments, Satterthwaite); where either fails, the factor is their root
    mean square. The end of a segment mirrors it. The factor
    only raises a scale, so the rule's false flag rate stays at most its threshold's.
    """
    g = scorer.group
    out = np.ones(d.shape)
    left = (shapes >= 0) & (shapes < fit_k)
    right = (shapes > fit_k) & (shapes <= 2 * fit_k)
    at = np.flatnonzero(left | right)
    if at.size == 0:
        return out
    dof = 3 if g.vector else 1  # per row: the quaternion's tangent space, or one channel
    for kf, pf, a in {(int(fit_k[i]), int(fit_p[i]), int(shapes[i])) for i in at}:
        mine = at[(fit_k[at] == kf) & (fit_p[at] == pf) & (shapes[at] == a)]
        r = rows[mine]
        j = np.arange(2 * kf)[None, :]
        inward = r[:, None] + (a + 1 + j if a < kf else -(2 * kf - a + 1 + j))
        inside = (inward >= scorer._seg_lo[r][:, None]) & (inward < scorer._seg_hi[r][:, None])
        inside[inside] = good[inward[inside]]
        ask = np.unique(inward[inside])
        if ask.size == 0:
            continue
        d_in = scorer._at_shape(kf, pf, a, ask, good, True)
        z = np.full(inward.shape + (d.shape[1],), np.nan)  # (rows, 2k, c)
        z[inside] = d_in[np.searchsorted(ask, inward[inside])] / scorer.scales[(kf, pf)][a]
        use = np.all(np.isfinite(z), axis=2)  # (rows, 2k)
        corr = residual_correlation(kf, pf, min(a, 2 * kf - a), 2 * kf)
        if use.all():  # the usual case (no gap or excluded row near): one pattern
            groups = [(use[0], np.arange(use.shape[0]))]
        else:
            patterns, which = np.unique(use, axis=0, return_inverse=True)
            order = np.argsort(which.ravel(), kind="stable")
            groups = zip(patterns, np.split(order, np.cumsum(np.bincount(which.ravel()))[:-1]),
                         strict=True)  # fmt: skip
        for pat, these in groups:
            if not pat.any():
                continue
            c = corr[np.ix_(pat, pat)]
            zi = z[these][:, pat]  # (rows, m, c)
            # the spread: a scaled chi-square with the moments of sum z^2
            tr, tr2 = dof * np.trace(c), dof * np.sum(c * c)  # (c symmetric)
            ss = np.sum(zi**2, axis=1)
            # the bias: a misfit of one sign over the next rows, sum z ~ N(0, 1'C1)
            bias = np.sum(zi, axis=1) ** 2 / np.sum(c)
            if g.vector:
                ss = np.sum(ss, axis=1, keepdims=True)
                bias = np.sum(bias, axis=1, keepdims=True)
            failed = ss * tr / tr2 > chi2_isf(EDGE_LEVEL / 2, tr * tr / tr2)
            failed |= bias > chi2_isf(EDGE_LEVEL / 2, dof)
            rms = np.sqrt(ss / tr)
            out[mine[these]] = np.where(failed, np.maximum(rms, 1.0), 1.0)
    return out
