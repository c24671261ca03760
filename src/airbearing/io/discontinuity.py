"""Discontinuities of a log: steps that no smooth motion explains, and stretches at another rate.

**Steps.** Two runs joined with continuous time (a second file appended, a block of
samples cut out) leave the logged rates and attitude with a jump at the join: the
samples before it follow one smooth motion, those after it another, and the two do
not meet. At a boundary between rows ``b - 1`` and ``b`` of a segment:

1. the *left fit* (the group's local polynomial ``(k, p)`` of the outlier rule,
   :mod:`airbearing.io.quality`, on the ``2k`` samples ``b - 2k .. b - 1``) and the
   *right fit* (on ``b .. b + 2k - 1``) are each extrapolated over the interval
   ``[t_{b-1}, t_b]``;
2. each must explain its own side: the left fit of the ``2k`` samples before ``b - 1``
   predicts ``b - 1``, the right fit of the ``2k`` samples after ``b`` predicts ``b``,
   both within the outlier threshold (so an isolated glitch, which disagrees with one
   side's own fit, is not a step: it is an outlier);
3. their disagreement ``D(tau) = x_L(tau) - x_R(tau)``, whose standard deviation under
   white noise of scale ``s`` is ``s * sqrt(sum w_L^2 + sum w_R^2)``, is scored at five
   times across the interval and the *smallest* score is kept: a kink (a torque
   switched, a rate limit reached between two samples) is continuous, so the two fits
   cross somewhere in the interval and its smallest score is noise; a step never
   meets;
4. the noise scale ``s`` is the outlier rule's own, for the extrapolated window shapes
   (all neighbours on one side: it includes their misfit of fast motion, measured on
   the log), times the local roughness factor at the row, so fast motion (a 4 rad/s
   spin at 10 Hz, a slew) is judged against the misfit it really leaves;
5. a step is a smallest score above :data:`STEP_THRESHOLD` (10 noise scales, against
   the outlier rule's 6: the min over the interval and the extrapolation make the
   score's tail heavier than a Gaussian's, and a missed step of 6-10 scales costs
   little, a false one breaks a segment) on any rate channel or the attitude.

Only boundaries next to an outlier suspect (the first pass of the rule) are tested,
and only where each side has ``2k + 1`` samples of the segment: a join within ``2k``
samples of a gap or of the log's ends is not found. A step breaks the segment there
as a gap does (the samples are kept; nothing is filled). Input channels (gimbals,
sliders, dipoles) are commanded and may step: they are not tested.

**Rate changes.** A stretch whose running median interval (over
``2 * _RATE_HALF + 1`` intervals) is beyond :data:`~airbearing.io.log.RATE_MISMATCH_FACTOR`
of ``1 / sensors.rate`` was sampled at another rate (a logger that slowed down): at a
slower rate every interval there is a gap, so its rows are one-sample segments no
tool uses. It is named once, with the row where it starts and the rate that follows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from airbearing.io.columns import RATE_MISMATCH_FACTOR
from airbearing.io.local_fits import row_any

__all__ = [
    "CHI2_3_THRESHOLD",
    "Discontinuity",
    "RowFinding",
    "STEP_THRESHOLD",
    "Z_THRESHOLD",
    "find_steps",
    "poly_weights",
    "rate_changes",
    "split_at",
]

# The thresholds of the outlier rule (airbearing.io.quality, which imports this module and
# exports them too) that the step detector shares.
#: Normalised residual (robust noise scales) above which one channel's sample is
#: suspect: two-sided Gaussian tail probability 2e-9 (scipy.stats.norm.isf(1e-9) = 5.998).
Z_THRESHOLD = 6.0
#: Squared normalised quaternion residual above which a sample is suspect:
#: chi-square with 3 degrees of freedom at tail probability 2e-9
#: (scipy.stats.chi2.isf(2e-9, 3) = 43.42).
CHI2_3_THRESHOLD = 43.42
_CHI2_3_MEDIAN = 2.3660  # scipy.stats.chi2.median(3)
_MAD_TO_SIGMA = 1.4826  # 1 / Phi^-1(3/4): MAD of a Gaussian -> its standard deviation


@dataclass(frozen=True)
class RowFinding:
    """Something found at one row of a log (an outlier, a step): where, in which columns,
    why and how strongly (see the subclasses)."""

    row: int
    t: float
    columns: tuple[str, ...]
    reason: str
    score: float

    def to_json(self) -> dict:
        """``{"row", "t", "columns", "reason", "score"}``."""
        return {
            "row": self.row,
            "t": self.t,
            "columns": list(self.columns),
            "reason": self.reason,
            "score": self.score,
        }


#: Smallest normalised disagreement (noise scales) between the left and right fits over
#: an interval above which the interval holds a step (module doc, step 5).
STEP_THRESHOLD = 10.0
_TAU = np.linspace(0.0, 1.0, 5)  # fractions of the interval at which D is scored
_MID = 2  # the middle of _TAU
_RATE_HALF = 5  # half-width (intervals) of the running median interval


@dataclass(frozen=True)
class Discontinuity(RowFinding):
    """A step between row ``row - 1`` and row ``row``: a new segment starts at ``row``.

    Attributes
    ----------
    row : int
        0-based data row where the new segment starts.
    t : float
        s, its logged time.
    columns : tuple of str
        The log columns that step.
    reason : str
        In words.
    score : float
        The smallest normalised disagreement over the interval, noise scales.
    """


def poly_weights(u: np.ndarray, p: int, at: np.ndarray, slope: bool = False) -> np.ndarray:
    """Least-squares polynomial weights on many small windows at once.

    For each window ``i`` (sample times ``u[i]``, strictly increasing, at least ``p + 1``
    of them), the weights ``w[i, j, :]`` with ``sum_c w[i, j, c] x[i, c]`` the value
    (``slope``: the derivative, per unit of ``u``) at ``at[i, j]`` of the degree-``p``
    polynomial fitted to ``x[i]`` by least squares: ``V(at) pinv(V(u))`` with ``V`` the
    Vandermonde matrix, as ``numpy.linalg.pinv`` gives it, without a decomposition per
    window. The polynomials orthonormal on each window's own times (Gram-Schmidt of
    ``s * phi_i`` against ``phi_0 .. phi_i``, done twice, on ``s`` the times centred and
    scaled to [-1, 1]) make the fit's projection ``sum_i phi_i(at) phi_i(u_c)``; the same
    recurrence evaluates them (and their derivatives) at ``at``. ``O(p^2)`` array
    operations over all windows instead of one SVD each; agrees with the pseudo-inverse
    to its rounding (``tests/io/test_poly_weights.py``).

    Parameters
    ----------
    u : numpy.ndarray
        (m, count) sample times of each window, any unit, increasing along a row.
    p : int
        Polynomial degree, ``p + 1 <= count``.
    at : numpy.ndarray
        (m, j) times (same unit) where the fit is evaluated.
    slope : bool
        Weights of the fit's derivative (per unit of ``u``) instead of its value.

    Returns
    -------
    numpy.ndarray
        (m, j, count) weights.
    """
    return _Basis(u, p).weights(at, slope)


class _Basis:
    """The polynomials of degree <= ``p`` orthonormal on each window's times ``u`` (m, count)
    (:func:`poly_weights`), built once and evaluated at any targets."""

    def __init__(self, u: np.ndarray, p: int) -> None:
        m, count = u.shape
        self.centre = 0.5 * (u[:, :1] + u[:, -1:])
        self.half = 0.5 * (u[:, -1:] - u[:, :1])
        s = (u - self.centre) / self.half
        phi = np.empty((m, p + 1, count))
        phi[:, 0] = 1.0 / np.sqrt(count)
        self.coef, self.norm = [], []  # phi_{i+1} = (s phi_i - sum_l c_l phi_l) / norm_i
        for i in range(p):
            v = s * phi[:, i]
            c = np.zeros((m, i + 1))
            for _ in range(2):  # twice is enough (Kahan): orthogonal to rounding
                d = np.einsum("mlc,mc->ml", phi[:, : i + 1], v)
                v = v - np.einsum("ml,mlc->mc", d, phi[:, : i + 1])
                c += d
            norm = np.sqrt(np.einsum("mc,mc->m", v, v))[:, None]
            phi[:, i + 1] = v / norm
            self.coef.append(c)
            self.norm.append(norm)
        self.phi, self.count = phi, count

    def weights(self, at: np.ndarray, slope: bool = False) -> np.ndarray:
        """(m, j, count) weights of the fit's value (``slope``: derivative) at ``at`` (m, j)."""
        m, p1 = self.phi.shape[:2]
        sa = (at - self.centre) / self.half
        psi = np.empty((m, p1, at.shape[1]))  # the orthonormal polynomials at `at`
        dpsi = np.zeros_like(psi)  # their derivatives in the scaled time
        psi[:, 0] = 1.0 / np.sqrt(self.count)
        for i, (c, norm) in enumerate(zip(self.coef, self.norm, strict=True)):
            psi[:, i + 1] = (sa * psi[:, i] - np.einsum("ml,mlj->mj", c, psi[:, : i + 1])) / norm
            if slope:
                dpsi[:, i + 1] = (
                    psi[:, i] + sa * dpsi[:, i] - np.einsum("ml,mlj->mj", c, dpsi[:, : i + 1])
                ) / norm
        if slope:
            return np.einsum("mij,mic->mjc", dpsi, self.phi) / self.half[:, :, None]
        return np.einsum("mij,mic->mjc", psi, self.phi)


#: Relative sample times equal to within 1 / this (periods) share their fit weights.
_PATTERN_GRID = 1e9


class _Fit:
    """The least-squares polynomials (degree ``p``) of the ``count`` samples starting at
    rows ``first`` (m,), times in ``period`` from ``origin`` (m,): :meth:`weights` at any
    targets, the windows' rows ``rows`` (m, count).

    The weights depend only on the sample and target times relative to the origin: on a
    regular grid every window has the same ones (times equal to 1e-9 of a period, far
    below any time a log resolves), so they are computed once and shared there."""

    def __init__(self, t, first, count, p, origin, period):
        self.rows = first[:, None] + np.arange(count)
        self.origin, self.period = origin, period
        u = (t[self.rows] - origin[:, None]) / period
        self._same = _one_pattern(u)
        self._u, self._p = u, p
        self.basis = _Basis(u[:1] if self._same else u, p)

    def weights(self, at, slope=False):
        """Weights (m, j, count) of the value (``slope``: the slope, per period) at the
        times ``at`` (m, j), s."""
        at = (at - self.origin[:, None]) / self.period
        if self._same and _one_pattern(at):
            w = self.basis.weights(at[:1], slope)
            return np.broadcast_to(w, (at.shape[0], *w.shape[1:]))
        if self._same:  # one window pattern, targets that differ: every window's own
            self.basis, self._same = _Basis(self._u, self._p), False
        return self.basis.weights(at, slope)


def _one_pattern(u: np.ndarray) -> bool:
    """Are all rows of ``u`` equal to 1 / :data:`_PATTERN_GRID`?"""
    key = np.round(u * _PATTERN_GRID)
    return bool(np.all(key == key[:1]))


def _weights(t, first, count, p, at, origin, period, slope=False):
    """Least-squares polynomial (degree ``p``) weights predicting the values (``slope``:
    the slopes, per ``period``) at times ``at`` (m, j) from the ``count`` samples starting
    at rows ``first`` (m,).

    Returns the weights (m, j, count) and the rows (m, count)."""
    fit = _Fit(t, first, count, p, origin, period)
    return fit.weights(at, slope), fit.rows


def _predict(w, rows, x):
    """sum_j w_j x_j: (m, j, count) weights, (m, count) rows -> (m, j, c)."""
    return np.einsum("mjc,mcd->mjd", w, x[rows])


#: The side fits tried, ``(samples, degree)``, besides the outlier rule's own ``(2k, p)``:
#: longer windows extrapolate with less noise where the motion allows a low degree.
SIDE_FITS: tuple[tuple[int, int], ...] = ((12, 2), (24, 3))


def _side(t, x, b, count, p, period, wrap, in_window=False):
    """Left and right fits of ``count`` samples at boundaries ``b``: their disagreement in
    value at :data:`_TAU` across the interval (m, tau, c) and in slope at its middle
    (m, c), with their noise gains, and each side's own one-step residual (normalised by
    ``sqrt(1 + h)``) of its last sample; ``in_window``: also the residuals of the two
    fits on their own samples (m, 2 count, c), a side that one polynomial does not
    explain (a block of glitches in it) being no side of a step. Each window's fit is
    built once and evaluated at all its targets."""
    t0, t1 = t[b - 1], t[b]
    at = t0[:, None] + (t1 - t0)[:, None] * _TAU
    mid = 0.5 * (t0 + t1)[:, None]
    left = _Fit(t, b - count, count, p, t0, period)
    right = _Fit(t, b, count, p, t0, period)
    w_l, w_r = left.weights(at), right.weights(at)
    v_l, v_r = left.weights(mid, slope=True), right.weights(mid, slope=True)
    d = _predict(w_l, left.rows, x) - _predict(w_r, right.rows, x)
    dv = _predict(v_l, left.rows, x)[:, 0] - _predict(v_r, right.rows, x)[:, 0]
    h = np.sum(w_l**2, axis=-1) + np.sum(w_r**2, axis=-1)
    hv = np.sum(v_l[:, 0] ** 2, axis=-1) + np.sum(v_r[:, 0] ** 2, axis=-1)
    e_l, e_r = _one_step(t, x, b, count, p, period, wrap)
    if wrap:
        d = np.mod(d + np.pi, 2 * np.pi) - np.pi
    if not in_window:
        return d, dv, h, hv, e_l, e_r
    out = []
    for fit in (left, right):
        e = x[fit.rows] - _predict(fit.weights(t[fit.rows]), fit.rows, x)
        out.append(np.mod(e + np.pi, 2 * np.pi) - np.pi if wrap else e)
    return d, dv, h, hv, e_l, e_r, np.concatenate(out, axis=1)


def _one_step(t, x, b, count, p, period, wrap):
    """Each side's own one-step residual at boundaries ``b`` (m, c), normalised by
    ``sqrt(1 + h)``: the last sample before ``b`` predicted by the ``count`` samples
    before it, the first sample from ``b`` by the ``count`` samples after it."""
    t0, t1 = t[b - 1], t[b]
    s_l, q_l = _weights(t, b - count - 1, count, p, t0[:, None], t0, period)
    s_r, q_r = _weights(t, b + 1, count, p, t1[:, None], t0, period)
    e_l = x[b - 1] - _predict(s_l, q_l, x)[:, 0]
    e_r = x[b] - _predict(s_r, q_r, x)[:, 0]
    if wrap:
        e_l, e_r = (np.mod(v + np.pi, 2 * np.pi) - np.pi for v in (e_l, e_r))
    e_l = e_l / np.sqrt(1.0 + np.sum(s_l[:, 0] ** 2, axis=-1))[:, None]
    e_r = e_r / np.sqrt(1.0 + np.sum(s_r[:, 0] ** 2, axis=-1))[:, None]
    return e_l, e_r


def _calibrate(g, t, segments, count, p, period):
    """Robust scale of the one-step residuals of a side fit, per channel (or one for a
    vector group), over up to 2000 boundaries spread over the log: noise plus the
    fit's own misfit of the motion, measured on the log. None if too few."""
    rows = []
    for a, b in segments:
        if b - a > 2 * count + 2:
            rows.append(np.arange(a + count + 1, b - count))
    if not rows:
        return None
    rows = np.concatenate(rows)
    rows = rows[np.unique(np.linspace(0, rows.size - 1, min(rows.size, 2000)).astype(int))]
    if rows.size < 8:
        return None
    e = np.concatenate(_one_step(t, g.values, rows, count, p, period, g.wrap))
    if g.vector:
        return np.array([np.sqrt(np.median(np.sum(e**2, axis=1)) / _CHI2_3_MEDIAN)])
    return _MAD_TO_SIGMA * np.median(np.abs(e - np.median(e, axis=0)), axis=0)


def find_steps(
    scorer, t: np.ndarray, period: float, switch: np.ndarray | None = None
) -> list[tuple[int, tuple[str, ...], float]]:
    """Steps of one channel group (module doc): ``(row, columns, score)`` each.

    Parameters
    ----------
    scorer : airbearing.io.quality_outliers._Scorer
        (passed in: this module is below io.quality, which calls it)
        The outlier rule's scorer of the group on the log's gap segments.
    t : numpy.ndarray
        s, sample times, shape (n,).
    period : float
        s, nominal sample interval (only scales the time axis of the fits).
    switch : numpy.ndarray or None
        (n,) bool: rows near a switch of a logged command (``quality_channels._switch_rows``).
        There a moving mass or a gimbal's momentum exchange may make the rate jump: the
        rates are not tested and the attitude only for a jump in value (its two fits
        may meet anywhere in the interval).
    """
    g = scorer.group
    k, p = scorer.fit
    n = t.size
    _, over = scorer(np.arange(n), np.ones(n, dtype=bool), exact=False)
    suspect = row_any(over)
    cand = np.flatnonzero(suspect[:-1] | suspect[1:]) + 1
    cand = np.unique(np.clip(cand[:, None] + np.arange(-1, 2), 1, n - 1))
    if cand.size == 0:  # no suspect: no boundary to test (and no side fit to calibrate)
        return []
    best = None  # the most sensitive side fit: smallest step it detects (value)
    for count, deg in ((2 * k, p), *SIDE_FITS):
        scale = _calibrate(g, t, scorer.segments, count, deg, period)
        if scale is None:
            continue
        scale = np.maximum(scale, g.floor)
        mid = np.array([count + 1])  # a regular interior boundary
        tt = np.arange(2 * count + 3, dtype=float) * period
        h0 = _side(tt, np.zeros((tt.size, 1)), mid, count, deg, period, False)[2][0, _MID]
        key = float(np.sum(np.log(scale))) + 0.5 * scale.size * float(np.log(h0))
        if best is None or key < best[0]:
            best = (key, count, deg, scale)
    if best is None:
        return []
    _, count, deg, base = best
    lo, hi = scorer._seg_lo[cand], scorer._seg_hi[cand]
    b = cand[(cand - count - 1 >= lo) & (cand + count <= hi - 1) & (scorer._seg_lo[cand - 1] == lo)]
    if b.size == 0:
        return []
    x = g.values
    d, dv, h, hv, e_l, e_r, e_in = _side(t, x, b, count, deg, period, g.wrap, in_window=True)
    # the local roughness a window's away on each side: a glitch (or the step itself)
    # right at the boundary must not inflate the scale that is to judge it
    local = np.maximum(scorer.local_at(b - count), scorer.local_at(b + count - 1))  # (m, c)
    # a noise-free channel's local factor is the outlier rule's change-of-slope floor
    # over its own noise scale (quality module doc, step 4): that floor itself, not
    # multiplied by this fit's misfit
    quiet = scorer._quiet[None, :]
    scale = np.where(quiet, np.maximum(base, scorer.noise * local), base[None, :] * local)
    at_switch = np.zeros(b.size, dtype=bool) if switch is None else switch[b - 1] | switch[b]
    if g.vector:
        explained = (np.sum(e_l**2, axis=1) / scale[:, 0] ** 2 <= CHI2_3_THRESHOLD) & (
            np.sum(e_r**2, axis=1) / scale[:, 0] ** 2 <= CHI2_3_THRESHOLD
        )
        z_in = np.sum(e_in**2, axis=2) / scale[:, :1] ** 2
        explained &= np.all(z_in <= CHI2_3_THRESHOLD, axis=1)
        z_tau = np.linalg.norm(d, axis=-1) / (scale[:, :1] * np.sqrt(h))  # (m, tau)
        z_slope = np.linalg.norm(dv, axis=-1) / (scale[:, 0] * np.sqrt(hv))
        z_slope = np.where(scorer._quiet[0], 0.0, z_slope)  # see below
        z = np.where(at_switch, np.min(z_tau, axis=1), np.maximum(z_tau[:, _MID], z_slope))
        z = np.repeat(z[:, None], len(g.columns), axis=1)
    else:
        explained = np.all(np.abs(e_l) / scale <= Z_THRESHOLD, axis=1)
        explained &= np.all(np.abs(e_r) / scale <= Z_THRESHOLD, axis=1)
        explained &= np.all(np.abs(e_in) / scale[:, None, :] <= Z_THRESHOLD, axis=(1, 2))
        z_tau = np.abs(d) / (scale[:, None, :] * np.sqrt(h)[..., None])  # (m, tau, c)
        z_min = np.min(z_tau, axis=1)
        if g.name == "attitude":  # no finite torque makes the rate jump: slopes meet too
            z_slope = np.abs(dv) / (scale * np.sqrt(hv)[:, None])
            # a noise-free (simulated) attitude shows every impulse of a moving mass as a
            # change of slope far above its floor: its slope is not tested, only its value
            z_slope = np.where(scorer._quiet[None, :], 0.0, z_slope)
            z = np.where(at_switch[:, None], z_min, np.maximum(z_tau[:, _MID], z_slope))
        else:  # a rate may kink (a torque switched): the two fits cross in the interval
            z = np.where(at_switch[:, None], 0.0, z_min)
    stepping = (z > STEP_THRESHOLD) & explained[:, None]
    score = np.where(stepping, z, 0.0).max(axis=1)
    # an interval shorter than half a period is a timing fault (reported as irregular):
    # values logged at shifted times are not a step of the motion
    irregular = np.diff(t) < 0.5 * period
    out = []
    for i in np.flatnonzero(score > 0):
        if irregular[max(b[i] - 4, 0) : b[i] + 3].any():
            continue
        near = np.abs(b - b[i]) <= count // 2
        if score[i] < np.max(score[near]):
            continue  # one step, one row: the best within half a window
        cols = tuple(c for c, s in zip(g.columns, stepping[i], strict=True) if s)
        row = _change_point(t, x, int(b[i]), count, deg, lo=int(scorer._seg_lo[b[i]]),
                            hi=int(scorer._seg_hi[b[i]]), period=period)  # fmt: skip
        out.append((row, cols, float(score[i])))
    return out


def _change_point(t, x, b, count, deg, *, lo, hi, period, reach=3) -> int:
    """The row within ``reach`` of ``b`` where two fits of degree ``deg``, one on each side
    of the break, leave the smallest sum of squared residuals on one fixed span: the
    disagreement tests find that a step is near, this says where (the side checks let a
    window straddle the step by a sample or two)."""
    a, z = max(lo, b - count - reach), min(hi, b + count + reach)
    best, best_rss = b, np.inf
    for c in range(max(b - reach, a + deg + 2), min(b + reach, z - deg - 2) + 1):
        rss = 0.0
        for s, e in ((a, c), (c, z)):
            u = (t[s:e] - t[c]) / period
            v = u[:, None] ** np.arange(deg + 1)
            coef, *_ = np.linalg.lstsq(v, x[s:e], rcond=None)
            rss += float(np.sum((x[s:e] - v @ coef) ** 2))
        if rss < best_rss:
            best, best_rss = c, rss
    return best


def split_at(segments, rows) -> tuple[tuple[int, int], ...]:
    """``segments`` with a new segment starting at each of ``rows`` (nothing dropped)."""
    rows = sorted(set(int(r) for r in rows))
    out = []
    for a, b in segments:
        start = a
        for r in (r for r in rows if a < r < b):
            out.append((start, r))
            start = r
        out.append((start, b))
    return tuple(out)


def rate_changes(t: np.ndarray, period: float, rate: float) -> tuple[dict, ...]:
    """Stretches sampled at another rate (module doc), each as a dict.

    Returns
    -------
    tuple of dict
        ``{"first_row", "last_row", "t0", "t1", "interval", "reason"}``: the rows of the
        stretch (the first is the first row after an interval at the other rate), its
        logged times (s), its median interval (s) and one sentence.
    """
    dt = np.diff(t)
    width = 2 * _RATE_HALF + 1
    if dt.size < width:
        return ()

    # a window whose every interval is within the factor has its median there too (the
    # division by period keeps order): the running median (a partition per window, 0.2 s
    # per 10^6 intervals) only of the other windows, which decide
    m = dt.size - width + 1
    hi, lo = dt[:m].copy(), dt[:m].copy()
    for j in range(1, width):
        np.maximum(hi, dt[j : j + m], out=hi)
        np.minimum(lo, dt[j : j + m], out=lo)
    inside = (hi / period <= RATE_MISMATCH_FACTOR) & (lo / period >= 1.0 / RATE_MISMATCH_FACTOR)
    ratio = np.full(m, 1.0)
    undecided = np.flatnonzero(~inside)
    if undecided.size:
        windows = sliding_window_view(dt, width)[undecided]
        ratio[undecided] = np.median(windows, axis=1) / period
    ratio = np.r_[np.full(_RATE_HALF, ratio[0]), ratio, np.full(_RATE_HALF, ratio[-1])]
    off = (ratio > RATE_MISMATCH_FACTOR) | (ratio < 1.0 / RATE_MISMATCH_FACTOR)
    out = []
    edges = np.flatnonzero(np.diff(np.r_[0, off.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # intervals a .. b - 1
        if b - a < width:
            continue
        median = float(np.median(dt[a:b]))
        first, last = int(a) + 1, int(b)
        gaps = median > period * RATE_MISMATCH_FACTOR
        what = (
            "every interval there is a gap (> 1.5 / rate): one-sample segments no tool uses"
            if gaps
            else "intervals there are irregular (< 0.5 / rate)"
        )
        out.append(
            {
                "first_row": first,
                "last_row": last,
                "t0": float(t[first]),
                "t1": float(t[last]),
                "interval": median,
                "reason": (
                    f"from row {first} (t = {t[first]:.6g} s) to row {last} "
                    f"(t = {t[last]:.6g} s) the sample interval is {median:.6g} s "
                    f"({1.0 / median:.6g} Hz), {median / period:.3g} x 1 / sensors.rate "
                    f"({rate:g} Hz): {what}; a logger that changed its rate?"
                ),
            }
        )
    return tuple(out)
