"""Quality of a log: segments, jitter and outliers (FORMATS.md, "Real logs are not perfect").

:func:`assess` says, for one log and its testbed, which rows form segments (runs of
samples between gaps), how irregular the sampling is, and which rows are
**outliers**: isolated samples that no smooth motion explains. Every tool leaves the
outlier rows out of its fits (``Log.usable_mask()``) and reports them by row (0-based
data rows, the same in a raw file and its imported log).

The outlier rule
----------------
A rigid body on an air bearing moves smoothly: between two samples its rate and its
attitude change by a smooth function of time. A glitch (a packet read as 0, a spike,
a quaternion written in another frame, an occluded motion-capture frame exported as
0, a marker swap, the first or last sample of a finite difference) is a sample that
disagrees with its neighbours by far more than the sensor noise. The rule, for each
segment (never across a gap) and each channel group:

1. **Channel groups.** The rates ``wx, wy, wz`` (``wz`` for dof 1) when the testbed
   has a gyro, each channel tested on its own; the attitude, either the quaternion
   (its four components as one vector, signs made continuous, see below) or the yaw
   (unwrapped within the segment). Sliders, dipoles and gimbal angles are commands
   or stepper positions, not smooth measurements, and are not tested.
2. **Leave-one-out residual.** Sample ``i`` is predicted by a polynomial in time of
   degree ``p`` fitted by least squares to its ``2k`` nearest samples of the same
   segment (``k`` each side; at a segment's ends the window slides inwards, so the
   first and last samples are extrapolated), *without* sample ``i`` and without the
   samples already found to be outliers, on the logged times (jitter is used as
   logged). The prediction is linear in the neighbours, ``x_hat_i = sum_j w_ij x_j``,
   so under white noise of scale ``s`` the residual ``x_i - x_hat_i`` has standard
   deviation ``s * sqrt(1 + sum_j w_ij^2)``; dividing by ``sqrt(1 + sum_j w_ij^2)``
   makes residuals of interior, edge and jittered samples comparable.
3. **Following fast motion.** The fit is tried with ``(k, p)`` = (3, 2), (4, 4) and
   (5, 6) and the one whose robust noise scale (step 4) is smallest is used. Under
   pure noise the three scales agree (the normalisation of step 2 makes them so);
   when the motion is fast for the sample rate (a 4 rad/s spin at 10 Hz, a 1.6 rad/s
   oscillation at 20 Hz) the low degree leaves a curvature residual and the higher
   degree, whose bias falls as ``(omega dt)^(p+2)``, removes it. So the scale
   measures the noise, not the model's curvature.
4. **Robust noise scale**, per channel over all segments: ``1.4826 * MAD`` of the
   normalised residuals (for the quaternion, ``sqrt(median(|r|^2) / 2.366)``, the
   median of chi-square with 3 degrees of freedom: attitude noise of ``sigma`` rad
   per axis moves the unit quaternion by ``sigma / 2`` per tangent axis, so
   ``|r|^2`` is chi-square(3) whatever the attitude, while single components are
   not identically distributed). The scale is never taken below the testbed's
   nominal noise (``sensors.gyro_noise``; ``sensors.attitude_noise``, halved for the
   quaternion) nor below ``1e-9`` of the channel's magnitude (noise-free
   simulations), so that a clean, noise-free log is not over-flagged.
5. **Threshold.** A sample is suspect when a channel's normalised residual exceeds
   6 scales (two-sided Gaussian tail 2e-9; for the quaternion, ``|r|^2`` above
   chi-square(3) at 2e-9, i.e. 43.4 squared scales). With 3 rate channels and the
   attitude on 10^5 samples the expected number of false flags on a clean log is
   ``10^5 * 4 * 2e-9 ~ 1e-3``. A real glitch of 20 noise scales gives a normalised
   residual of about 20 / sqrt(1.5) = 16 in the interior and still above 6 at a
   segment's end.
6. **Masking, one glitch at a time.** A glitch also pulls the fits of its
   neighbours, so only the suspects that are the largest within ``k`` samples are
   taken, they are left out of every fit, and the residuals are computed again;
   this repeats until no new suspect remains. A sample is an outlier if its final
   residual (its neighbours' outliers left out) is still above the threshold.
7. **Isolated only.** A run of 1 or 2 consecutive suspects is an outlier run. A run
   of 3 or more is not an isolated glitch but something the log really did (an
   impact, a sustained fault, a step): it is reported as ``unexplained`` and kept
   in the fits (nothing is silently dropped).

Noise-free first-sample artefacts (a rate of 0 at a segment's first sample because
the exporter differentiated the attitude) are found by the extrapolated fit of
step 2: the residual is the whole rate, many noise scales unless the platform is
at rest, in which case 0 is not wrong.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from airbearing.errors import InputError

if TYPE_CHECKING:
    from airbearing.io.log import Log
    from airbearing.io.testbed import Testbed

__all__ = [
    "CHI2_3_THRESHOLD",
    "FITS",
    "Outlier",
    "LogQuality",
    "Z_THRESHOLD",
    "assess",
    "find_outliers",
]

#: Normalised residual (robust noise scales) above which one channel's sample is
#: suspect: two-sided Gaussian tail probability 2e-9 (scipy.stats.norm.isf(1e-9) = 5.998).
Z_THRESHOLD = 6.0
#: Squared normalised quaternion residual above which a sample is suspect:
#: chi-square with 3 degrees of freedom at tail probability 2e-9
#: (scipy.stats.chi2.isf(2e-9, 3) = 43.42).
CHI2_3_THRESHOLD = 43.42
_CHI2_3_MEDIAN = 2.3660  # scipy.stats.chi2.median(3)
_MAD_TO_SIGMA = 1.4826  # 1 / Phi^-1(3/4): MAD of a Gaussian -> its standard deviation
#: The local fits tried, ``(k, p)``: k samples each side, polynomial degree p.
FITS: tuple[tuple[int, int], ...] = ((3, 2), (4, 4), (5, 6))
_MAX_RUN = 2  # longest run of consecutive suspects that is an isolated glitch
_RELATIVE_FLOOR = 1e-9  # scale floor relative to the channel's magnitude
_MAX_PASSES = 200


@dataclass(frozen=True)
class Outlier:
    """One outlier row.

    Attributes
    ----------
    row : int
        0-based data row.
    t : float
        Logged time, s.
    columns : tuple of str
        The log columns whose value no smooth motion explains.
    reason : str
        In words: which channel, how far from the local smooth fit.
    score : float
        The largest normalised residual, in robust noise scales.
    """

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


@dataclass(frozen=True)
class LogQuality:
    """Segments, sampling and outliers of one log (:func:`assess`).

    Attributes
    ----------
    n_rows : int
        Rows of the log.
    period : float
        s, nominal sample interval ``1 / sensors.rate``.
    median_interval : float
        s, median of the logged intervals.
    segments : tuple of (int, int)
        ``(start, stop)`` rows of each segment (0-based, stop exclusive); a gap is an
        interval longer than 1.5 periods.
    segment_times : tuple of (float, float)
        s, first and last logged time of each segment.
    jitter : float
        Largest ``|dt / period - 1|`` over the intervals within segments (0 for a
        perfectly regular log; at most 0.5 unless some intervals are irregular).
    irregular_rows : tuple of int
        Rows whose interval from the previous row is shorter than half a period
        (used with their logged time; not an error).
    outliers : tuple of Outlier
        Isolated samples no smooth motion explains, by row.
    outlier_rows : tuple of int
        Their rows, sorted.
    unexplained_rows : tuple of int
        Rows in runs of 3 or more consecutive suspects: not isolated, kept in fits.
    noise : dict of str to float
        The robust noise scale of each tested channel (``"wx"``, ``"yaw"``,
        ``"quaternion"``...), in the channel's unit.
    fits : dict of str to (int, int)
        The local fit ``(k, p)`` used for each channel group (``"rates"``,
        ``"attitude"``).
    unchecked_rows : tuple of int
        Rows of segments too short for any local fit (fewer than 4 samples).
    """

    n_rows: int
    period: float
    median_interval: float
    segments: tuple[tuple[int, int], ...]
    segment_times: tuple[tuple[float, float], ...]
    jitter: float
    irregular_rows: tuple[int, ...]
    outliers: tuple[Outlier, ...]
    outlier_rows: tuple[int, ...]
    unexplained_rows: tuple[int, ...] = ()
    noise: dict[str, float] = field(default_factory=dict)
    fits: dict[str, tuple[int, int]] = field(default_factory=dict)
    unchecked_rows: tuple[int, ...] = ()

    @property
    def n_segments(self) -> int:
        """Number of segments."""
        return len(self.segments)

    def usable_mask(self) -> np.ndarray:
        """True for every row a fit may use (False at outlier rows), shape (n_rows,)."""
        mask = np.ones(self.n_rows, dtype=bool)
        mask[list(self.outlier_rows)] = False
        return mask

    def to_json(self) -> dict:
        """The JSON contract.

        Returns
        -------
        dict
            ``segments`` (count), ``segment_rows`` ([[start, stop], ...], stop
            exclusive), ``segment_times`` ([[t0, t1], ...], s), ``outlier_rows``,
            ``outliers`` ([{row, t, columns, reason, score}]), ``jitter``,
            ``median_interval`` (s), ``period`` (s), ``n_rows``, ``irregular_rows``,
            ``unexplained_rows``, ``unchecked_rows``, ``noise`` (per channel) and
            ``fits`` (per group, ``[k, p]``).
        """
        return {
            "n_rows": self.n_rows,
            "segments": len(self.segments),
            "segment_rows": [list(s) for s in self.segments],
            "segment_times": [list(s) for s in self.segment_times],
            "outlier_rows": list(self.outlier_rows),
            "outliers": [o.to_json() for o in self.outliers],
            "jitter": self.jitter,
            "median_interval": self.median_interval,
            "period": self.period,
            "irregular_rows": list(self.irregular_rows),
            "unexplained_rows": list(self.unexplained_rows),
            "unchecked_rows": list(self.unchecked_rows),
            "noise": dict(self.noise),
            "fits": {k: list(v) for k, v in self.fits.items()},
        }


# ----------------------------------------------------------------------------
# leave-one-out local polynomial fits


def _loo(
    t: np.ndarray, x: np.ndarray, good: np.ndarray, k: int, p: int, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """Leave-one-out residuals of one segment.

    Parameters
    ----------
    t : (m,) times; x : (m, c) values; good : (m,) samples a fit may use.

    Returns
    -------
    r : (m, c) residual ``x_i - x_hat_i`` (NaN where no fit is possible)
    h : (m,) ``sum_j w_ij^2``, the noise gain of the prediction
    """
    m = t.size
    g = np.flatnonzero(good)
    ng = g.size
    idx = np.arange(m)
    pos = np.searchsorted(g, idx)  # usable samples before i
    own = good.astype(int)
    left, right = pos, ng - pos - own
    a = np.minimum(k, left)
    b = np.minimum(right, 2 * k - a)  # slide inwards at the ends
    a = np.minimum(left, 2 * k - b)
    j = np.arange(2 * k)[None, :]
    take = np.where(
        j < a[:, None], pos[:, None] - a[:, None] + j, pos[:, None] + own[:, None] + j - a[:, None]
    )
    valid = j < (a + b)[:, None]
    nb = g[np.clip(take, 0, max(ng - 1, 0))] if ng else np.zeros_like(take)
    tau = (t[nb] - t[:, None]) / scale
    V = tau[..., None] ** np.arange(p + 1)
    Vw = V * valid[..., None]
    ok = (a + b) >= p + 1
    r = np.full(x.shape, np.nan)
    h = np.full(m, np.nan)
    if not ok.any():
        return r, h
    A = np.einsum("mja,mjb->mab", Vw[ok], V[ok])
    e0 = np.zeros(p + 1)
    e0[0] = 1.0
    try:
        z = np.linalg.solve(A, np.broadcast_to(e0, (A.shape[0], p + 1))[..., None])[..., 0]
    except np.linalg.LinAlgError:
        z = np.einsum("mab,b->ma", np.linalg.pinv(A), e0)
    w = np.einsum("mja,ma->mj", Vw[ok], z)
    r[ok] = x[ok] - np.einsum("mj,mjc->mc", w, x[nb[ok]])
    h[ok] = np.sum(w * w, axis=1)
    return r, h


@dataclass
class _Group:
    name: str  # "rates" or "attitude"
    columns: tuple[str, ...]  # log columns
    values: np.ndarray  # (n, c), prepared (signs continuous, yaw unwrapped)
    vector: bool  # True: one chi-square(c-1) test on the vector (quaternion)
    floor: np.ndarray  # (c,) or (1,) scale floor
    wrap: bool = False  # residual modulo 2 pi (yaw)


def _residuals(
    group: _Group, t: np.ndarray, segments, good: np.ndarray, k: int, p: int, scale: float
) -> np.ndarray:
    """Normalised residuals ``r / sqrt(1 + h)``, shape (n, c); NaN where unchecked."""
    out = np.full(group.values.shape, np.nan)
    for start, stop in segments:
        if stop - start < 4:
            continue
        r, h = _loo(t[start:stop], group.values[start:stop], good[start:stop], k, p, scale)
        if group.wrap:
            r = np.mod(r + np.pi, 2 * np.pi) - np.pi
        out[start:stop] = r / np.sqrt(1.0 + h)[:, None]
    return out


def _scales(group: _Group, d: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Robust noise scale per channel (or one for a vector group), floored."""
    rows = mask & np.all(np.isfinite(d), axis=1)
    if not rows.any():
        return group.floor.copy()
    if group.vector:
        s = np.array([np.sqrt(np.median(np.sum(d[rows] ** 2, axis=1)) / _CHI2_3_MEDIAN)])
    else:
        dev = d[rows] - np.median(d[rows], axis=0)
        s = _MAD_TO_SIGMA * np.median(np.abs(dev), axis=0)
    return np.maximum(s, group.floor)


def _scores(group: _Group, d: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-row score (noise scales) and per-channel exceedance, NaN -> 0."""
    d = np.nan_to_num(d, nan=0.0)
    if group.vector:
        z2 = np.sum(d * d, axis=1) / s[0] ** 2
        score = np.sqrt(z2)
        over = (z2 > CHI2_3_THRESHOLD)[:, None] & np.ones(d.shape[1], dtype=bool)
        return score, over
    z = np.abs(d) / s
    return np.max(z, axis=1), z > Z_THRESHOLD


@dataclass(frozen=True)
class _GroupResult:
    flagged: np.ndarray  # (n,) bool: outlier rows (isolated runs of 1-2)
    unexplained: np.ndarray  # (n,) bool: rows in longer runs of suspects
    score: np.ndarray  # (n,) final normalised score, noise scales
    over: np.ndarray  # (n, c) per-channel exceedance at the final pass
    noise: np.ndarray  # robust noise scale per channel (one for a vector group)
    fit: tuple[int, int]  # (k, p) used


def find_outliers(group: _Group, t: np.ndarray, segments, scale: float) -> _GroupResult:
    """Run the rule of the module docstring on one channel group."""
    n = t.size
    all_good = np.ones(n, dtype=bool)
    best: tuple[float, tuple[int, int]] | None = None
    for k, p in FITS:
        d = _residuals(group, t, segments, all_good, k, p, scale)
        key = float(np.sum(np.log(_scales(group, d, all_good))))
        if best is None or key < best[0]:
            best = (key, (k, p))
    assert best is not None
    k, p = best[1]
    excluded = np.zeros(n, dtype=bool)
    seg_id = np.zeros(n, dtype=int)
    for i, (start, stop) in enumerate(segments):
        seg_id[start:stop] = i
    for _ in range(_MAX_PASSES):
        d = _residuals(group, t, segments, ~excluded, k, p, scale)
        score, over = _scores(group, d, _scales(group, d, ~excluded))
        suspect = over.any(axis=1) & ~excluded
        if not suspect.any():
            break
        # only the largest suspect within k samples (same segment) is taken this pass
        take = []
        for i in np.flatnonzero(suspect):
            near = np.arange(max(i - k, 0), min(i + k + 1, n))
            near = near[(seg_id[near] == seg_id[i]) & suspect[near]]
            if score[i] >= np.max(score[near]):
                take.append(i)
        excluded[take] = True
    # final residuals with every excluded sample left out of the others' fits
    d = _residuals(group, t, segments, ~excluded, k, p, scale)
    s = _scales(group, d, ~excluded)
    score, over = _scores(group, d, s)
    suspect = excluded & over.any(axis=1)
    flagged = np.zeros(n, dtype=bool)
    unexplained = np.zeros(n, dtype=bool)
    rows = np.flatnonzero(suspect)
    if rows.size:
        breaks = np.flatnonzero((np.diff(rows) != 1) | (np.diff(seg_id[rows]) != 0)) + 1
        for run in np.split(rows, breaks):
            (flagged if run.size <= _MAX_RUN else unexplained)[run] = True
    return _GroupResult(flagged, unexplained, score, over, s, (k, p))


# ----------------------------------------------------------------------------
# channel groups of a log


def _continuous_signs(q: np.ndarray, segments) -> np.ndarray:
    """``q`` with signs chosen so that each sample agrees with its most similar predecessor.

    Each sample is compared with the previous 3 (within its segment) and takes its
    sign from the one with the largest ``|q_i . q_j|``, so that one or two glitched
    samples cannot flip the rest of the segment (q and -q are the same attitude).
    """
    n = q.shape[0]
    parent = np.arange(n)
    rel = np.ones(n)
    best = np.zeros(n)
    seg_start = np.zeros(n, dtype=int)
    for start, stop in segments:
        seg_start[start:stop] = start
    for lag in (1, 2, 3):
        i = np.arange(lag, n)
        i = i[i - lag >= seg_start[i]]
        dot = np.sum(q[i] * q[i - lag], axis=1)
        better = np.abs(dot) > best[i]
        i, dot = i[better], dot[better]
        best[i] = np.abs(dot)
        parent[i] = i - lag
        rel[i] = np.where(dot < 0, -1.0, 1.0)
    # sign_i = rel_i * sign_parent(i): pointer doubling to the segment's first sample
    while np.any(parent != parent[parent]):
        rel = rel * rel[parent]
        parent = parent[parent]
    rel = rel * rel[parent]  # roots have rel 1
    return q * rel[:, None]


def _groups(log: Log, testbed: Testbed, segments) -> list[_Group]:
    groups = []
    sensors = testbed.sensors
    rates = log.rates()
    if rates is not None:
        cols = ("wx", "wy", "wz") if rates.shape[1] == 3 else ("wz",)
        mag = np.maximum(np.max(np.abs(rates), axis=0), 1.0)
        floor = np.maximum(sensors.gyro_noise, _RELATIVE_FLOOR * mag)
        groups.append(_Group("rates", cols, rates, False, floor))
    use_yaw = testbed.body.dof == 1 and log.has("yaw")
    if use_yaw:
        yaw = log.column("yaw")
        for start, stop in segments:
            yaw[start:stop] = np.unwrap(yaw[start:stop])
        mag = max(float(np.max(np.abs(yaw))), 1.0)
        floor = np.array([max(sensors.attitude_noise, _RELATIVE_FLOOR * mag)])
        groups.append(_Group("attitude", ("yaw",), yaw[:, None], False, floor, wrap=True))
    elif log.has("qw", "qx", "qy", "qz"):
        q = _continuous_signs(log.quaternions(), segments)
        floor = np.array([max(0.5 * sensors.attitude_noise, _RELATIVE_FLOOR)])
        groups.append(_Group("attitude", ("qw", "qx", "qy", "qz"), q, True, floor))
    return groups


def _reason(group: _Group, cols: tuple[str, ...], score: float, logged_zero: bool) -> str:
    what = "rate" if group.name == "rates" else "attitude"
    return (
        f"{what} {', '.join(cols)}{' logged as 0,' if logged_zero else ''} {score:.3g} noise "
        "scales from the smooth fit of its neighbours"
    )


def assess(log: Log, testbed: Testbed) -> LogQuality:
    """Segments, jitter and outliers of a log (the rule is in the module docstring).

    Parameters
    ----------
    log : Log
        A validated log (``read_log``, ``Log(...)``); its columns are read as they are.
    testbed : Testbed
        Its sample rate defines gaps (interval > 1.5 / rate) and jitter; its sensors
        say which columns are measurements (``sensors.gyro``) and give the noise
        floors (``gyro_noise``, ``attitude_noise``).

    Returns
    -------
    LogQuality

    Raises
    ------
    InputError
        If ``testbed`` is not a Testbed.
    """
    from airbearing.io.log import segments_of
    from airbearing.io.testbed import Testbed

    if not isinstance(testbed, Testbed):
        raise InputError(f"{log.source}: assess needs a Testbed, got {type(testbed).__name__}")
    t = log.data["t"].to_numpy(dtype=float)
    n = t.size
    period = testbed.sensors.dt
    segments = segments_of(t, period)
    dt = np.diff(t)
    inside = dt <= 1.5 * period
    jitter = float(np.max(np.abs(dt[inside] / period - 1.0))) if inside.any() else 0.0
    irregular = tuple(int(i) + 1 for i in np.flatnonzero(dt < 0.5 * period))
    flagged_cols: dict[int, list[str]] = {}
    reasons: dict[int, list[str]] = {}
    scores: dict[int, float] = {}
    unexplained = np.zeros(n, dtype=bool)
    noise: dict[str, float] = {}
    fits: dict[str, tuple[int, int]] = {}
    for group in _groups(log, testbed, segments):
        res = find_outliers(group, t, segments, period)
        fits[group.name] = res.fit
        if group.vector:
            noise["quaternion"] = float(res.noise[0])
        else:
            noise.update({c: float(v) for c, v in zip(group.columns, res.noise, strict=True)})
        unexplained |= res.unexplained
        for i in (int(i) for i in np.flatnonzero(res.flagged)):
            cols = tuple(c for c, o in zip(group.columns, res.over[i], strict=True) if o)
            cols = cols or group.columns
            zero = bool(np.all(log.data.loc[i, list(cols)].to_numpy(dtype=float) == 0))
            flagged_cols.setdefault(i, []).extend(cols)
            reasons.setdefault(i, []).append(_reason(group, cols, float(res.score[i]), zero))
            scores[i] = max(scores.get(i, 0.0), float(res.score[i]))
    outliers = tuple(
        Outlier(
            row=i,
            t=float(t[i]),
            columns=tuple(flagged_cols[i]),
            reason="; ".join(reasons[i]),
            score=scores[i],
        )
        for i in sorted(flagged_cols)
    )
    unchecked = tuple(r for start, stop in segments if stop - start < 4 for r in range(start, stop))
    return LogQuality(
        n_rows=n,
        period=period,
        median_interval=float(np.median(dt)) if dt.size else period,
        segments=segments,
        segment_times=tuple((float(t[a]), float(t[b - 1])) for a, b in segments),
        jitter=jitter,
        irregular_rows=irregular,
        outliers=outliers,
        outlier_rows=tuple(o.row for o in outliers),
        unexplained_rows=tuple(
            int(i) for i in np.flatnonzero(unexplained) if int(i) not in flagged_cols
        ),
        noise=noise,
        fits=fits,
        unchecked_rows=unchecked,
    )
