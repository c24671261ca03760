"""Is a fit adequate? What its residual leaves above the noise, is it white, what it follows.

Every discrepancy fit is judged on its residual:

``gap_over_floor``
    The fit's gap over the noise floor estimated from the data (both in the gap's unit).
    Within the model it is about ``sqrt(1 - n_free / n_res)`` (slightly below 1).
``whiteness_p``
    A portmanteau test of the normalised primary residual
    (:func:`airbearing.analysis.shooting.errors.normalised_residuals`): the Ljung-Box
    statistic (``statsmodels.stats.diagnostic.acorr_ljungbox``'s, :func:`ljung_box_p`) of
    every log segment and every axis at ``min(LB_LAGS, n // 5)`` lags, combined by the
    SMALLEST p-value times the number of tests (Bonferroni, capped at 1): the probability,
    for white residuals, that at least one segment looks as correlated as the worst one.
``gap_over_noise``
    The gap over the measurement noise: the floor when the noise is white; when the
    estimator found it coloured (an AR(1) model of the primary output,
    :mod:`airbearing.analysis.shooting.measurement_noise`), its marginal standard
    deviation, which the floor (a difference estimate: it sees the noise's fast part only)
    underestimates.
``structure_remains``
    ``(whiteness_p < WHITENESS_ALPHA and gap_over_noise > GAP_ABOVE)`` or the fit's
    process-noise intensity is significant (``fit.extra["process_noise"]["significant"]``,
    when the estimator provides it), or ``gap_over_floor > GAP_CLEAR`` (2: whatever the
    whiteness test says, twice the floor is not the noise), or, on a reaction-wheel log,
    ``wheel_gap_over_floor > GAP_CLEAR``. Both conditions are needed
    for the first arm: a residual at the floor may be slightly correlated by the fit
    itself, and a residual just above a floor that the difference estimator
    underestimates may still be white.
``wheel_gap_over_floor``
    Reaction-wheel logs (output group ``ws``): the RMS wheel-speed residual over the wheel
    speeds' own noise floor (:class:`~airbearing.analysis.shooting.logs.NoiseFloor`
    ``wheel``): what acts on a wheel alone and the Model misses shows there, not in the
    gap.
``correlation_time_s``
    Where the autocorrelation of the normalised residual (pooled over segments and axes,
    each segment weighted by its length) first falls below ``1/e``, linearly
    interpolated between lags, times the median sample period, s.
``follows``
    The residual (gap unit) regressed, within each segment, on four functions of each
    of: the yaw angle (``sin, cos`` of ``yaw`` and ``2 yaw``), the rate (``w``, ``|w|``,
    ``w |w|``, ``sign w`` about the yaw axis, or ``wx, wy, wz, |w|`` on dof 3) and time
    (Legendre polynomials of degree 1-4 over each segment, one set per segment), each
    group with the segment's mean; ``R^2`` of each group (about the segments' means), and
    the one that explains most.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.polynomial import legendre

from airbearing import quaternion as quat
from airbearing.analysis.shooting import errors

__all__ = [
    "GAP_ABOVE",
    "LB_LAGS",
    "WHITENESS_ALPHA",
    "Adequacy",
    "adequacy",
    "correlation_time",
    "follows",
    "structure_rule",
    "whiteness",
]

#: Level below which the combined Ljung-Box p-value says "not white".
WHITENESS_ALPHA = 1e-3
#: The gap must exceed the noise floor by this factor for structure to remain (the floor is
#: a robust difference estimate: a few % off on 10^3 samples, see :mod:`.data`).
GAP_ABOVE = 1.1
#: Above this many noise floors structure remains whatever the whiteness test says (a white
#: residual twice the floor is a misfit or a floor the data's differences cannot see).
GAP_CLEAR = 2.0
#: Most lags of the Ljung-Box test (fewer on short segments: ``n // 5``).
LB_LAGS = 20
#: Fewest samples of a segment tested for whiteness.
MIN_SEGMENT = 25
#: Most lags of the pooled autocorrelation (the correlation time and the report's plot).
ACF_LAGS = 600
#: The keys of the estimator's process-noise record that the JSON carries.
PROCESS_NOISE_KEYS = (
    "intensity",
    "unit",
    "lr",
    "p",
    "significant",
    "horizon_s",
    "kappa",
    "piece_s",
    "floor_kappa",
    "lr_bottom",
)
#: Smallest R^2 with which the residual is said to follow the angle, the rate or time.
FOLLOWS_MIN = 0.05
#: Names of the regressor groups of :func:`follows`, in words.
GROUP_WORDS = {"angle": "the yaw angle", "rate": "the rate", "time": "time"}


def _segments(raw) -> list:
    """``(source, rows, t, r)`` per log segment of the estimator's normalised residuals."""
    out = []
    for item in raw:
        if hasattr(item, "r"):
            source, rows, t, r = item.source, item.rows, item.t, item.r
        else:
            source, rows, t, r = item
        r = np.asarray(r, dtype=float)
        out.append(
            (int(source), np.asarray(rows), np.asarray(t, dtype=float), r.reshape(len(r), -1))
        )
    return out


def whiteness(segments) -> tuple[float, int]:
    """Combined Ljung-Box p-value of normalised residual segments (module doc).

    Parameters
    ----------
    segments : list of ndarray (n, n_axes)
        Normalised residuals of each segment, in time order.

    Returns
    -------
    p : float
        Smallest p-value times the number of tests, capped at 1 (NaN when no segment is
        long enough).
    tests : int
    """
    ps = []
    for r in segments:
        n = r.shape[0]
        if n < MIN_SEGMENT:
            continue
        h = int(min(LB_LAGS, n // 5))
        for a in range(r.shape[1]):
            x = r[:, a]
            if not np.all(np.isfinite(x)) or np.ptp(x) == 0:
                continue
            ps.append(ljung_box_p(x, h))
    if not ps:
        return math.nan, 0
    return float(min(1.0, min(ps) * len(ps))), len(ps)


def ljung_box_p(x: np.ndarray, h: int) -> float:
    """The Ljung-Box p-value of the series ``x`` at ``h`` lags (statsmodels' ``q_stat``).

    statsmodels' ``acorr_ljungbox`` takes the autocovariances from the whole correlation
    of ``x`` with itself (``numpy.correlate``, every lag: quadratic in the samples, 0.6 s
    per axis of a 30,001-row segment and 20 s of an hour's); here ``acovf`` computes lags
    ``0..h`` only and ``q_stat`` the statistic and its chi-square tail, the same numbers to
    rounding (a relative 1e-15).
    """
    # statsmodels: 0.7-2.1 s CPU to import, loaded only when this runs
    from statsmodels.tsa.stattools import acovf, q_stat

    avf = acovf(x, adjusted=False, demean=True, fft=False, nlag=h)
    _, p = q_stat(avf[1 : h + 1] / avf[0], x.shape[0])
    return float(p[-1])


def pooled_acf(segments, nlags: int = ACF_LAGS) -> np.ndarray:
    """Autocorrelation of the residual at lags ``0..nlags``, pooled over segments and axes
    (each weighted by its number of samples at that lag)."""
    num = np.zeros(nlags + 1)
    den = np.zeros(nlags + 1)
    for r in segments:
        n = r.shape[0]
        if n < 3:
            continue
        x = r - r.mean(axis=0)
        var = float(np.sum(x**2))
        if var <= 0:
            continue
        m = min(nlags, n - 1)
        nfft = 1 << int(math.ceil(math.log2(2 * n)))
        f = np.fft.rfft(x, nfft, axis=0)
        c = np.fft.irfft(f * np.conj(f), nfft, axis=0)[: m + 1].sum(axis=1)
        # each segment's autocovariance sums weighted by its own variance (the biased ACF)
        num[: m + 1] += c
        den[: m + 1] += var
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = num / den
    return acf[den > 0] if den[0] > 0 else np.array([1.0])


def correlation_time(acf: np.ndarray, dt: float) -> float:
    """s, where ``acf`` first falls below ``1/e``, interpolated between lags (module doc)."""
    level = math.exp(-1.0)
    below = np.flatnonzero(acf < level)
    if below.size == 0:
        return float(len(acf) - 1) * dt
    j = int(below[0])
    if j == 0:
        return 0.0
    a, b = float(acf[j - 1]), float(acf[j])
    return float((j - 1 + (a - level) / (a - b)) * dt)


def _legendre(x: np.ndarray, deg: int) -> np.ndarray:
    return np.column_stack([legendre.legval(x, np.eye(deg + 1)[d]) for d in range(1, deg + 1)])


def follows(residual, yaw, rate, t, segment) -> dict:
    """``R^2`` of the residual on functions of the yaw angle, the rate and time (module doc).

    Parameters
    ----------
    residual : ndarray (n, c)
        Residual in the gap's unit.
    yaw : ndarray (n,)
        rad, the yaw angle at each sample.
    rate : ndarray (n, a)
        rad/s, the angular rate (one axis: about the yaw axis).
    t : ndarray (n,)
        s.
    segment : ndarray (n,) of int
        Segment label of each sample (means and time polynomials per segment).

    Returns
    -------
    dict
        ``{"angle": R2, "rate": R2, "time": R2, "most": group or None}``.
    """
    y = np.asarray(residual, dtype=float).reshape(len(residual), -1)
    seg = np.asarray(segment)
    labels = np.unique(seg)
    means = (seg[:, None] == labels[None, :]).astype(float)
    # residual about each segment's mean (what the segment's own constant explains is no
    # one's)
    y0 = y - means @ np.linalg.lstsq(means, y, rcond=None)[0]
    ss = float(np.sum(y0**2))
    w = np.asarray(rate, dtype=float).reshape(len(rate), -1)
    if w.shape[1] == 1:
        wz = w[:, 0]
        g_rate = np.column_stack([wz, np.abs(wz), wz * np.abs(wz), np.sign(wz)])
    else:
        g_rate = np.column_stack([w, np.linalg.norm(w, axis=1)])
    tt = np.zeros(len(t))
    for lab in labels:
        m = seg == lab
        lo, hi = float(np.min(t[m])), float(np.max(t[m]))
        tt[m] = 2 * (t[m] - lo) / max(hi - lo, 1e-12) - 1
    groups = {
        "angle": np.column_stack([np.sin(yaw), np.cos(yaw), np.sin(2 * yaw), np.cos(2 * yaw)]),
        "rate": g_rate,
        # a slow drift has its own shape in each segment: polynomials per segment
        "time": np.hstack([_legendre(tt, 4) * means[:, [j]] for j in range(len(labels))]),
    }
    out: dict = {}
    for name, X in groups.items():
        A = np.hstack([means, X])
        scale = np.sqrt(np.sum(A**2, axis=0))
        A = A / np.where(scale > 0, scale, 1.0)
        coef = np.linalg.lstsq(A, y, rcond=1e-10)[0]
        e = y - A @ coef
        out[name] = float(1.0 - np.sum(e**2) / ss) if ss > 0 else 0.0
    best = max(groups, key=lambda k: out[k])
    out["most"] = best if out[best] > 0 else None
    return out


def torque_words(pn: dict) -> str:
    """The sentence of a significant unexplained torque (``fit.extra["process_noise"]``)."""
    p = pn.get("p", math.nan)
    p_txt = "p < 1e-16" if p == 0 else f"p {p:.2g}"
    h = pn.get("horizon_s")
    return (
        f"an unexplained torque is significant (intensity {pn.get('intensity', 0):.3g} "
        f"{pn.get('unit', '')}, {p_txt}"
        + (f"; the model predicts to the noise over about {h:.3g} s" if h else "")
        + ")"
    )


@dataclass(frozen=True, eq=False)
class Adequacy:
    """The adequacy verdict of one fit (module doc).

    Attributes
    ----------
    gap_over_floor : float
        The gap of one trajectory per segment (the estimator's most continuous fit) over
        the noise floor; without process noise, the fit's own gap.
    pieces_gap_over_floor : float
        The fit's own gap (its pieces, at the estimated horizon) over the floor.
    whiteness_p : float
        Bonferroni-combined Ljung-Box p-value (NaN: no segment long enough).
    tests : int
        Number of Ljung-Box tests combined.
    structure_remains : bool
    correlation_time_s : float
        s.
    follows : dict
        ``R^2`` per regressor group and the group that explains most (:func:`follows`).
    explained_fraction : float or None
        Fraction of the nominal gap's excess over the floor (in variance) that the named
        effects explain, ``(gap_0^2 - gap^2) / (gap_0^2 - floor^2)``; None without effects.
    process_noise : dict or None
        The fit's ``extra["process_noise"]`` when the estimator provides it.
    measurement_noise : dict or None
        The primary output's AR(1) noise when the estimator found it coloured: ``phi``,
        ``s``, ``correlation_time_s``, ``lr``, ``p`` and ``noise_over_floor``.
    note : str
        The verdict in words.
    acf : ndarray
        Pooled autocorrelation at lags ``0..``, for the report.
    dt : float
        s, the lag step of ``acf``.
    """

    gap_over_floor: float
    pieces_gap_over_floor: float
    whiteness_p: float
    tests: int
    structure_remains: bool
    correlation_time_s: float
    follows: dict
    explained_fraction: float | None
    process_noise: dict | None
    note: str
    measurement_noise: dict | None = None
    acf: np.ndarray = field(repr=False, default_factory=lambda: np.ones(1))
    dt: float = 0.0
    series: dict = field(repr=False, default_factory=dict)
    wheel_gap_over_floor: float | None = None

    @property
    def noise_over_floor(self) -> float:
        """The measurement noise's standard deviation over the floor (1 when white)."""
        m = self.measurement_noise
        return float(m["noise_over_floor"]) if m else 1.0

    @property
    def gap_over_noise(self) -> float:
        """The gap over the measurement noise (the floor when white; module doc)."""
        return float(self.gap_over_floor / self.noise_over_floor)

    def noise_words(self) -> str:
        """The coloured measurement noise in words (empty when white)."""
        m = self.measurement_noise
        if not m:
            return ""
        return (
            f"the measurement noise is coloured (AR(1), coefficient {m['phi']:.3g} per sample, "
            f"correlated over {m['correlation_time_s']:.3g} s; {m['noise_over_floor']:.3g} x "
            "the floor the data's differences see)"
        )

    @property
    def at_noise(self) -> bool:
        """True when the residual is at the noise (no structure remains)."""
        return not self.structure_remains

    def words(self, named: bool) -> str:
        """What remains, in words (empty when the residual is at the noise)."""
        if not self.structure_remains:
            return ""
        parts = []
        w = self.wheel_gap_over_floor
        if w is not None and w > GAP_CLEAR:
            parts.append(f"the wheel speeds' residual is {w:.3g} x their noise floor")
        if named and self.explained_fraction is not None:
            parts.append(
                f"the named effects explain {100 * self.explained_fraction:.0f} % of the gap's "
                "excess over the noise"
            )
        pn = self.process_noise
        if self.measurement_noise:
            parts.append(self.noise_words())
        what = "the measurement noise" if self.measurement_noise else "the noise floor"
        of_floor = f" ({self.gap_over_floor:.3g} x the floor)" if self.measurement_noise else ""
        if pn and pn.get("significant"):
            parts.append(torque_words(pn))
            parts.append(
                f"over whole segments {self.gap_over_noise:.3g} x {what} remains{of_floor}"
            )
        else:
            parts.append(f"{self.gap_over_noise:.3g} x {what} remains{of_floor}")
        if self.measurement_noise and self.gap_over_noise <= GAP_CLEAR:
            parts.append("which may be that noise alone (the data cannot tell it from a misfit)")
        if pn and pn.get("significant"):
            pass  # the pieces' residual is white by construction: the horizon says it
        elif self.dt and self.correlation_time_s < self.dt:
            parts.append(
                "the whitened residual uncorrelated from one sample to the next"
                if self.measurement_noise
                else "uncorrelated from one sample to the next"
            )
        else:
            parts.append(f"correlated over {self.correlation_time_s:.3g} s")
        f = self.follows
        if f.get("most") and f[f["most"]] < FOLLOWS_MIN:
            parts.append(
                f"it follows neither the yaw angle, the rate nor time (R^2 below {FOLLOWS_MIN:g})"
            )
        elif f.get("most"):
            others = ", ".join(
                f"{GROUP_WORDS[g]} {f[g]:.2f}" for g in ("angle", "rate", "time") if g != f["most"]
            )
            parts.append(
                f"it follows {GROUP_WORDS[f['most']]} most (R^2 {f[f['most']]:.2f}; {others})"
            )
        return "structure remains: " + ", ".join(parts)

    def to_json(self) -> dict:
        def num(x):
            return None if x is None or not np.isfinite(x) else float(x)

        out = {
            "gap_over_floor": num(self.gap_over_floor),
            "gap_over_noise": num(self.gap_over_noise),
            "pieces_gap_over_floor": num(self.pieces_gap_over_floor),
            "whiteness_p": num(self.whiteness_p),
            "whiteness_test": (
                f"Ljung-Box per segment and axis at up to {LB_LAGS} lags, {self.tests} tests, "
                "combined: smallest p times the number of tests (Bonferroni)"
            ),
            "structure_remains": bool(self.structure_remains),
            "correlation_time_s": num(self.correlation_time_s),
            "explained_fraction": num(self.explained_fraction),
            "follows": {k: (v if k in ("most", "of") else num(v)) for k, v in self.follows.items()},
            "rule": (
                f"structure remains when whiteness_p < {WHITENESS_ALPHA:g} and gap_over_noise > "
                f"{GAP_ABOVE:g}, or the process noise is significant, or gap_over_floor > "
                f"{GAP_CLEAR:g} (gap_over_noise: over the measurement noise, the floor when "
                "it is white)"
            ),
            "note": self.note,
            "measurement_noise": (
                None
                if not self.measurement_noise
                else {k: num(v) for k, v in self.measurement_noise.items()}
            ),
        }
        if self.wheel_gap_over_floor is not None:
            out["wheel_gap_over_floor"] = num(self.wheel_gap_over_floor)
        if self.process_noise is not None:
            out["process_noise"] = {
                k: (num(v) if isinstance(v, float) else v)
                for k, v in self.process_noise.items()
                if k in PROCESS_NOISE_KEYS
            }
        return out


def _states(problem, fit, datas):
    """Residual (gap unit), yaw, rate, time and segment label at every usable window sample."""
    # analysis.discrepancy.replay loads pandas: 0.5 s CPU, loaded only when this runs
    from airbearing.analysis.discrepancy.replay import primary_series

    s = primary_series(problem, fit.delta, fit.p)
    w = problem.windows
    Y = problem.outputs_at(fit.delta, fit.p)[w.weight > 0]
    d0 = datas[0]
    rate = Y[:, problem.model.index(list(d0.rate_names), "y")]
    src, rows = s["source"], s["rows"]
    if d0.q is None:
        yaw = np.array([datas[i].att[r, 0] for i, r in zip(src, rows, strict=True)])
    else:
        q = np.array([datas[i].q[r] for i, r in zip(src, rows, strict=True)])
        yaw = quat.yaw_of(q)
    t = np.array([datas[i].t[r] for i, r in zip(src, rows, strict=True)])
    seg = np.zeros(len(rows), dtype=int)
    k = 0
    for i, d in enumerate(datas):
        for a, b in d.segments:
            seg[(src == i) & (rows >= a) & (rows < b)] = k
            k += 1
    return s["residual"], yaw, rate, t, seg, src


def structure_rule(
    whiteness_p: float,
    gap_over_floor: float,
    significant_noise: bool,
    gap_over_noise: float | None = None,
) -> bool:
    """``structure_remains`` from the whiteness p-value, the gap over the floor and over
    the measurement noise (default: the floor) and the process-noise test (module doc).

    A coloured noise model never hides a gap above twice the floor: that a correlated
    residual is the sensor's and not a misfit is what the data cannot prove.
    """
    noise = gap_over_floor if gap_over_noise is None else gap_over_noise
    white_fails = bool(np.isfinite(whiteness_p) and whiteness_p < WHITENESS_ALPHA)
    return bool(
        (white_fails and noise > GAP_ABOVE) or significant_noise or gap_over_floor > GAP_CLEAR
    )


def _measurement_noise(problem, fit, floor) -> dict | None:
    """The primary output's coloured noise of ``fit`` (the problem's, which ``fit`` was made
    with) with its level over the floor."""
    mn, g = getattr(problem, "measurement_noise", None), problem.outputs[0]
    if mn is None or g not in mn.ar:
        return None
    m = mn.to_json()[g]
    sigma = problem.sigma_rate if g == "rate" else problem.sigma_att
    level = mn.level(g) * sigma / max(floor.value, 1e-300)
    return {**m, "noise_over_floor": float(level)}


def _defects(problem, fit, datas):
    """The unexplained torque at each hand-over of linked pieces: the whitened rate defects
    (process-noise rows of the residual), with yaw, rate, time and segment there; None
    without process-noise rows."""
    r = np.asarray(fit.extra.get("r", ()))
    n_meas = int(getattr(problem, "n_meas", r.size))
    w = problem.windows
    if r.size <= n_meas or w.link is None:
        return None
    nd, n_att, n_rate = problem.n_delta, problem.n_att, problem.n_rate
    js = np.flatnonzero(np.asarray(w.link, dtype=bool))
    if js.size < 8 or r.size < n_meas + nd * (w.n - 1):
        return None
    D = np.array([r[n_meas + j * nd + n_att : n_meas + j * nd + n_att + n_rate] for j in js])
    nxt = js + 1
    rows, src = w.rows[nxt, 0], w.source[nxt]
    Y = problem.outputs_at(fit.delta, fit.p)
    d0 = datas[0]
    rate = Y[nxt, 0][:, problem.model.index(list(d0.rate_names), "y")]
    if d0.q is None:
        yaw = np.array([datas[i].att[k, 0] for i, k in zip(src, rows, strict=True)])
    else:
        yaw = quat.yaw_of(np.array([datas[i].q[k] for i, k in zip(src, rows, strict=True)]))
    t = np.array([datas[i].t[k] for i, k in zip(src, rows, strict=True)])
    seg = np.zeros(js.size, dtype=int)
    lab = 0
    for i, d in enumerate(datas):
        for a, b in d.segments:
            seg[(src == i) & (rows >= a) & (rows < b)] = lab
            lab += 1
    return D, yaw, rate, t, seg


def adequacy(problem, fit, floor, datas, *, gap_before: float | None = None) -> Adequacy:
    """The adequacy verdict of ``fit`` (module doc).

    Parameters
    ----------
    problem : ShootingProblem
        The problem ``fit`` solved.
    fit : Fit
    floor : NoiseFloor
        The noise estimated from the data.
    datas : sequence of ReplayData
        The logs of ``problem`` (``windows.source`` indexes them).
    gap_before : float, optional
        The nominal model's gap (same unit), for the fraction the named effects explain.

    Returns
    -------
    Adequacy
    """
    pn = fit.extra.get("process_noise") if isinstance(fit.extra, dict) else None
    # on linked pieces the fit's own gap is the short horizon's; the most continuous fit
    # the estimator reached (one trajectory per segment) says what the model leaves
    gap = float(fit.gap)
    if pn and np.isfinite(pn.get("gap_whole", np.nan)):
        gap = max(gap, float(pn["gap_whole"]))
    ratio = float(gap / max(floor.value, 1e-300))
    ratio_pieces = float(fit.gap / max(floor.value, 1e-300))
    raw = errors.normalised_residuals(problem, fit)
    segs = _segments(raw)
    p, tests = whiteness([r for _, _, _, r in segs])
    dts = [np.median(np.diff(t)) for _, _, t, _ in segs if len(t) > 1]
    dt = float(np.median(dts)) if dts else float(datas[0].dt)
    acf = pooled_acf([r for _, _, _, r in segs])
    # the estimator's own correlation time (the one its HAC bandwidth uses), else ours
    ct = getattr(errors, "correlation_time", None)
    tau = float(ct(raw)) if ct is not None and raw and hasattr(raw[0], "r") else None
    tau = correlation_time(acf, dt) if tau is None else tau
    res, yaw, rate, t, seg, src = _states(problem, fit, datas)
    fol = follows(res, yaw, rate, t, seg)
    if pn and pn.get("significant"):
        # what the model misses is in the pieces' hand-overs, not in their residual
        dfx = _defects(problem, fit, datas)
        if dfx is not None:
            fol = {**follows(*dfx), "of": "the unexplained torque at the pieces' hand-overs"}
    significant_noise = bool(pn and pn.get("significant"))
    mnoise = _measurement_noise(problem, fit, floor)
    level = mnoise["noise_over_floor"] if mnoise else 1.0
    remains = structure_rule(p, ratio, significant_noise, ratio / level)
    wheel = None
    if "ws" in problem.outputs:
        wheel = _wheel_gap_over_floor(problem, fit, floor)
        remains = remains or wheel > GAP_CLEAR
    explained = None
    if gap_before is not None:
        # both over whole segments when the estimator reached them (the search passes the
        # nominal's whole-segment gap)
        excess = gap_before**2 - floor.value**2
        if excess > 0:
            explained = float(np.clip((gap_before**2 - gap**2) / excess, 0.0, 1.0))
    a = Adequacy(
        gap_over_floor=ratio,
        pieces_gap_over_floor=ratio_pieces,
        whiteness_p=p,
        tests=tests,
        structure_remains=remains,
        correlation_time_s=tau,
        follows=fol,
        explained_fraction=explained,
        process_noise=dict(pn) if pn else None,
        note="",
        measurement_noise=mnoise,
        acf=acf,
        dt=dt,
        series={"residual": res, "yaw": yaw, "rate": rate, "t": t, "source": src},
        wheel_gap_over_floor=wheel,
    )
    if remains:
        note = a.words(named=explained is not None)
    else:
        what = "the measurement noise" if mnoise else "the noise floor"
        # no test when the segments are too short for Ljung-Box: said, never "p nan"
        white = (
            f"whiteness p {p:.2g} (Ljung-Box, {tests} tests)"
            if np.isfinite(p)
            else "whiteness not tested (segments too short for Ljung-Box)"
        )
        note = f"the residual is at the noise: {ratio / level:.3g} x {what}, {white}"
        if mnoise:
            note += "; " + a.noise_words()
    return _with_note(a, note)


def _with_note(a: Adequacy, note: str) -> Adequacy:
    return replace(a, note=note)


def _wheel_gap_over_floor(problem, fit, floor) -> float:
    """The wheel speeds' RMS residual over their noise floor: each wheel's residual over its
    own level (a rig's tachometers need not be alike), RMS over wheels and rows."""
    w = floor.wheel_weights
    if np.ptp(w) == 0 and np.ptp(problem.sigma_ws_axes) == 0:
        return problem.noise_rms(fit.extra["r"])["ws"] / max(floor.wheel_weight, 1e-300)
    r = problem.raw_measurement(fit.extra["r"])
    sel = (problem.group == problem.outputs.index("ws")) & problem.usable
    c = problem.component[sel]
    return float(np.sqrt(np.mean((problem.sigma_ws_axes[c] * r[sel] / w[c]) ** 2)))
