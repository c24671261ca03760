"""The numerics of the outlier rule: leave-one-out local polynomial fits and running medians.

:mod:`airbearing.io.quality` states the rule (which samples are suspect, which
explanation wins, the reasons); this module holds the arithmetic it runs on every
row of a log, each in two forms where speed matters: a per-row reference (one
least-squares solve per row, the definition) and a fast path for regular windows
(one set of weights per window shape) that gives the same numbers
(``tests/io/test_log_quality_fast.py`` checks it against the reference).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = [
    "LOCAL",
    "REGULAR_ULPS",
    "row_all",
    "row_any",
    "row_max",
    "row_sum",
    "loo",
    "loo_reference",
    "noise_gain",
    "residual_correlation",
    "regular_span",
    "regular_weights",
    "window_median",
    "window_shape",
]

LOCAL = 25  # half-width (samples) of the running median that gives the local scale


# ----------------------------------------------------------------------------
# reductions across the few columns of each row
#
# numpy reduces a short last axis of a long (n, c) array row by row, 10-30 times slower
# than the same operations column by column (np.max(z, axis=1) of 333,000 x 3: 64 ms
# against 2 ms); these give the same numbers.


def row_any(b: np.ndarray) -> np.ndarray:
    """``b.any(axis=1)`` of a 2-D bool array, column by column."""
    out = b[:, 0].copy()
    for j in range(1, b.shape[1]):
        out |= b[:, j]
    return out


def row_all(b: np.ndarray) -> np.ndarray:
    """``b.all(axis=1)`` of a 2-D bool array, column by column."""
    out = b[:, 0].copy()
    for j in range(1, b.shape[1]):
        out &= b[:, j]
    return out


def row_max(z: np.ndarray) -> np.ndarray:
    """``np.max(z, axis=1)`` of a 2-D float array (NaN propagates), column by column."""
    out = z[:, 0].copy()
    for j in range(1, z.shape[1]):
        np.maximum(out, z[:, j], out=out)
    return out


def row_sum(p: np.ndarray) -> np.ndarray:
    """``np.sum(p, axis=1)`` of a 2-D float array of fewer than 8 columns: their sum in
    order from 0, which is what numpy's pairwise summation does below 8 terms (the same
    numbers, signed zeros too: tests/io/test_log_quality_fast.py)."""
    if p.shape[1] >= 8:
        return np.sum(p, axis=1)
    out = p[:, 0] + 0.0  # (a new array; -0.0 -> 0.0 as numpy's sum)
    for j in range(1, p.shape[1]):
        out += p[:, j]
    return out


# ----------------------------------------------------------------------------
# leave-one-out local polynomial fits


def window_shape(
    m: int, k: int, rows: np.ndarray, shape: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """Left and right neighbours ``(a, b)`` of each row's window in a segment of ``m`` rows.

    ``shape`` None: ``k`` each side, sliding inwards at the segment's ends; else
    ``shape`` left and ``2k - shape`` right where that fits, ``(0, 0)`` (no fit) elsewhere.
    """
    left, right = rows, m - 1 - rows  # samples of the segment before and after each row
    if shape is None:
        a = np.minimum(k, left)
        b = np.minimum(right, 2 * k - a)  # slide inwards at the ends
        a = np.minimum(left, 2 * k - b)
    else:
        fits = (left >= shape) & (right >= 2 * k - shape)
        a = np.where(fits, shape, 0)
        b = np.where(fits, 2 * k - shape, 0)
    return a, b


@lru_cache(maxsize=64)
def regular_weights(k: int, p: int, a: int) -> np.ndarray:
    """Prediction weights ``w_j`` of the fit ``(k, p)`` with ``a`` left neighbours on a
    regular grid, in window order (``a`` left, then ``2k - a`` right), read-only.

    The same least-squares solve as :func:`loo_reference` on the times of a regular
    window: a polynomial fit's value at ``tau = 0`` does not depend on the time unit,
    so these are the weights of every regular window of that shape, whatever its
    interval.
    """
    tau = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)].astype(float) / (k + 1)
    powers = tau[:, None] ** np.arange(p + 1)[None, :]
    gram = powers.T @ powers
    e0 = np.zeros(p + 1)
    e0[0] = 1.0
    w = powers @ np.linalg.solve(gram, e0)
    w.flags.writeable = False
    return w


def loo(
    t: np.ndarray,
    x: np.ndarray,
    good: np.ndarray,
    k: int,
    p: int,
    scale: float,
    rows: np.ndarray,
    shape: int | None = None,
    fast: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leave-one-out residuals of some rows of one segment (fast where sampling is regular).

    The same numbers as :func:`loo_reference` (the parameters and returns are its
    own). A row whose window is complete (``2k`` neighbours, none of them excluded
    by ``good``) and regular (the ``2k`` intervals of its span agree to within the
    rounding of the logged times, :func:`regular_span`) has the prediction weights
    of a regular grid for its window shape (:func:`regular_weights`, one small
    solve per shape), so its residual is a fixed linear combination of its
    neighbours: ``2k`` shifted multiply-adds over all such rows at once instead of
    one Gram solve per row. Every other row (jittered or irregular sampling, a
    neighbour already excluded, a segment shorter than ``2k + 1``) goes through the
    per-row solve. The two agree to the rounding of the logged times: on a
    regular window the per-row solve's times differ from the regular grid by
    nothing more. ``fast``: :func:`regular_span` of these rows, when the caller has it.
    """
    m = t.size
    a, b = window_shape(m, k, rows, shape)
    if fast is None:
        fast = regular_span(t, good, rows, a, b, k)
    if not fast.any():
        return loo_reference(t, x, good, k, p, scale, rows, shape)
    r = np.full((rows.size, x.shape[1]), np.nan)
    h = np.full(rows.size, np.nan)
    slow = ~fast
    if slow.any():
        r[slow], h[slow], _ = loo_reference(t, x, good, k, p, scale, rows[slow], shape)
    for left in np.flatnonzero(np.bincount(a[fast], minlength=2 * k + 1)):
        pos = np.flatnonzero(fast & (a == left))  # positions in rows (sorted)
        if pos[-1] - pos[0] + 1 == pos.size:  # one run of positions: slices
            pos = slice(int(pos[0]), int(pos[-1]) + 1)
        at = rows[pos]
        w = regular_weights(k, p, int(left))
        offsets = np.r_[-np.arange(left, 0, -1), np.arange(1, 2 * k - left + 1)]
        lo, hi = int(at[0]), int(at[-1]) + 1
        if hi - lo == at.size:  # consecutive rows (sorted): shifted slices, no gathers
            pred = w[0] * x[lo + offsets[0] : hi + offsets[0]]
            for off, wj in zip(offsets[1:], w[1:], strict=True):
                pred += wj * x[lo + off : hi + off]
            r[pos] = x[lo:hi] - pred
        else:
            pred = w[0] * x[at + offsets[0]]
            for off, wj in zip(offsets[1:], w[1:], strict=True):
                pred += wj * x[at + off]
            r[pos] = x[at] - pred
        h[pos] = float(w @ w)
    return r, h, a


#: Intervals within this many units in the last place of the segment's largest |t|
#: of each other count as equal (the rounding of logged times on a regular grid).
REGULAR_ULPS = 4


def regular_span(
    t: np.ndarray, good: np.ndarray, rows: np.ndarray, a: np.ndarray, b: np.ndarray, k: int
) -> np.ndarray:
    """True where a row's window is complete (``a + b = 2k``, every neighbour good) and
    regular (its ``2k`` intervals equal to within :data:`REGULAR_ULPS` of rounding)."""
    full = (a + b) == 2 * k
    if rows.size == 0 or not full.any():
        return full
    m = t.size
    tol = REGULAR_ULPS * float(np.spacing(max(abs(float(t[0])), abs(float(t[-1])))))
    first = np.where(full, rows - a, 0)  # first row of each span (2k + 1 rows)
    if rows.size * 4 < m:  # a few rows: look at their spans only
        span = np.minimum(first[:, None] + np.arange(2 * k + 1)[None, :], m - 1)
        ok = full & np.all(good[span] | (span == rows[:, None]), axis=1)
        dt = np.diff(t[span], axis=1)
        return ok & (np.max(dt, axis=1) - np.min(dt, axis=1) <= tol)
    # many rows: the spread of the 2k intervals and the excluded count of every span
    # of the segment, from shifted arrays (the same comparisons, without the gathers)
    dt = np.diff(t)
    starts = max(m - 2 * k, 0)  # spans that fit: first row 0 .. m - 2k - 1
    hi_dt, lo_dt = dt[:starts].copy(), dt[:starts].copy()
    for j in range(1, 2 * k):
        np.maximum(hi_dt, dt[j : j + starts], out=hi_dt)
        np.minimum(lo_dt, dt[j : j + starts], out=lo_dt)
    regular = np.zeros(m, dtype=bool)
    regular[:starts] = hi_dt - lo_dt <= tol
    bad = np.concatenate(([0], np.cumsum(~good)))
    last = np.minimum(first + 2 * k + 1, m)
    excluded = bad[last] - bad[first] - (~good[rows])
    return full & regular[first] & (excluded == 0)


def loo_reference(
    t: np.ndarray,
    x: np.ndarray,
    good: np.ndarray,
    k: int,
    p: int,
    scale: float,
    rows: np.ndarray,
    shape: int | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leave-one-out residuals of some rows of one segment, one least-squares solve per row.

    Parameters
    ----------
    t : (m,) times of the segment; x : (m, c) values; good : (m,) samples a fit may
    use; k, p : window half-width and degree; scale : time unit of the fit, s;
    rows : rows (of the segment) to predict; shape : force this many left
    neighbours (and ``2k - shape`` right ones); None: ``k`` each side, sliding
    inwards at the segment's ends.

    Returns
    -------
    r : (len(rows), c) residual ``x_i - x_hat_i`` (NaN where no fit is possible)
    h : (len(rows),) ``sum_j w_ij^2``, the noise gain of the prediction
    a : (len(rows),) left neighbours used (the window's shape)
    """
    m = t.size
    a, b = window_shape(m, k, rows, shape)
    j = np.arange(2 * k)[None, :]
    # the window is the 2k nearest samples in time; samples already found to be
    # outliers are left out of it (not replaced by farther ones: the span, and with
    # it the fit's misfit, stays that of a clean window)
    nb_all = np.where(
        j < a[:, None], rows[:, None] - a[:, None] + j, rows[:, None] + 1 + j - a[:, None]
    )
    nb_all = np.clip(nb_all, 0, max(m - 1, 0))
    valid = (j < (a + b)[:, None]) & good[nb_all]
    r = np.full((rows.size, x.shape[1]), np.nan)
    h = np.full(rows.size, np.nan)
    count = np.sum(valid, axis=1)
    ok = count >= (p + 1 if shape is None else 2 * k)
    if not ok.any():
        return r, h, a
    nb = nb_all[ok]
    valid = valid[ok]
    # times in units of the window's half-width (|tau| <~ 2): a well-conditioned Gram matrix
    tau = (t[nb] - t[rows[ok], None]) / (scale * (k + 1))
    powers = np.empty(tau.shape + (p + 1,))
    powers[..., 0] = 1.0
    for e in range(1, p + 1):
        powers[..., e] = powers[..., e - 1] * tau
    vw = powers * valid[..., None]
    gram = np.matmul(vw.transpose(0, 2, 1), powers)
    e0 = np.zeros((gram.shape[0], p + 1, 1))
    e0[:, 0, 0] = 1.0
    try:
        z = np.linalg.solve(gram, e0)[..., 0]
    except np.linalg.LinAlgError:
        z = np.linalg.pinv(gram)[:, :, 0]
    w = np.matmul(vw, z[..., None])[..., 0]
    r[ok] = x[rows[ok]] - np.matmul(w[:, None, :], x[nb])[:, 0, :]
    h[ok] = np.sum(w * w, axis=1)
    return r, h, a


def noise_gain(k: int, p: int, a: int) -> float:
    """``sum_j w_j^2`` of the fit ``(k, p)`` with ``a`` left neighbours on a regular grid."""
    tau = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)].astype(float)
    w = np.linalg.pinv(np.vander(tau, p + 1, increasing=True))[0]
    return float(w @ w)


@lru_cache(maxsize=64)
def residual_correlation(k: int, p: int, a: int, m: int) -> np.ndarray:
    """Correlation of the normalised residuals of ``m`` consecutive rows under white noise.

    Each row ``i = 1 .. m`` (after a row 0) is predicted by the fit ``(k, p)`` with
    ``a`` left neighbours on a regular grid (:func:`regular_weights`), its residual
    divided by ``sqrt(1 + h)``: unit variance each, correlated where the windows
    overlap. Returns the ``(m, m)`` matrix, read-only.
    """
    w = regular_weights(k, p, a)
    offsets = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)]
    rows = np.zeros((m, m + 2 * k + 1))
    for j in range(m):
        i = j + a  # (the first predicted row's window starts at column 0)
        rows[j, i] = 1.0
        rows[j, i + offsets] -= w
    rows /= np.sqrt(1.0 + float(w @ w))
    out = rows @ rows.T
    out.flags.writeable = False
    return out


#: Rows per block of :func:`window_median` (a block holds 51 values per row and channel).
MEDIAN_BLOCK = 8192


def window_median(
    values: np.ndarray, lo: np.ndarray, hi: np.ndarray, rows: np.ndarray, min_periods: int
) -> np.ndarray:
    """Centred running median over ``2 * LOCAL + 1`` samples at some rows, per column.

    The window of row ``i`` is clipped to its segment ``[lo_i, hi_i)``; NaN values are
    left out, and the median is NaN where fewer than ``min_periods`` (at least 1)
    values remain. As pandas' ``rolling(2 * LOCAL + 1, center=True,
    min_periods=...).median()`` on each segment: the middle value of an odd count,
    the mean ``(low + high) / 2`` of the two middle values of an even count.
    """
    out = np.empty((rows.size, values.shape[1]))
    offsets = np.arange(-LOCAL, LOCAL + 1)
    last = values.shape[0] - 1
    for b0 in range(0, rows.size, MEDIAN_BLOCK):
        block = slice(b0, b0 + MEDIAN_BLOCK)
        idx = rows[block, None] + offsets[None, :]
        inside = (idx >= lo[block, None]) & (idx < hi[block, None])
        window = values[np.clip(idx, 0, last)]  # (rows, 51, columns)
        window[~inside] = np.nan
        window.sort(axis=1)  # NaN last
        count = np.sum(~np.isnan(window), axis=1)  # (rows, columns)
        mid = count // 2
        high = np.take_along_axis(window, np.minimum(mid, 2 * LOCAL)[:, None, :], axis=1)[:, 0]
        low = np.take_along_axis(window, np.maximum(mid - 1, 0)[:, None, :], axis=1)[:, 0]
        med = np.where(count % 2 == 1, high, (low + high) / 2)
        out[block] = np.where(count >= max(min_periods, 1), med, np.nan)
    return out
