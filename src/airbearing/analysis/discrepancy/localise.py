"""Where the residual of a replay lives: per axis, over time, against the state, in frequency."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.discrepancy.replay import primary_series
from airbearing.analysis.filters import welch
from airbearing.analysis.shooting import Fit, ShootingProblem
from airbearing.analysis.shooting.logs import NoiseFloor

__all__ = ["Localisation", "localise"]

#: The residual is "above the floor" when its RMS exceeds the floor by this factor.
ABOVE = 1.1
#: A feature is "largest" somewhere when it exceeds elsewhere by this factor.
CONTRAST = 1.5


def _rms(x) -> float:
    x = np.asarray(x)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


@dataclass(frozen=True, eq=False)
class Localisation:
    """Where the residual of a fit lives (:func:`localise`): sentences and the numbers behind.

    Attributes
    ----------
    words : tuple of str
        The sentences a person reads.
    unit : str
        The gap unit (rad/s with a gyro, rad for attitude-only logs).
    residual : numpy.ndarray
        The primary output residual at every usable sample (``unit``), one column per axis.
    rows, source : numpy.ndarray
        The log row and the log index of each residual sample.
    axis_rms : numpy.ndarray
        RMS residual per axis (``unit``).
    window_gap, window_t, window_source : numpy.ndarray
        Per window: its gap (``unit``), its start time (s) and its log.
    vs_rate : numpy.ndarray
        RMS of |residual| by quarter of |w|, slowest first (``unit``).
    after_reversal, elsewhere : float or None
        RMS of |residual| within 1 s after a rate reversal and elsewhere (``unit``).
    tilt : tuple or None
        dof 3: ``(lower quartile deg, RMS below, upper quartile deg, RMS above)``.
    field_vertical : bool or None
        dof 3 with a cage field: whether the field is vertical.
    gimbal : tuple or None
        cmg: ``(quartile deg, RMS below, quartile deg, RMS above)`` of mean |delta|.
    gimbal_busy : tuple or None
        cmg: RMS while the gimbals turn fast and while they hold (``unit``).
    spectrum : tuple
        ``(frequency Hz, PSD per axis, white-noise level per axis)``.
    """

    words: tuple
    unit: str
    residual: np.ndarray = field(repr=False)
    rows: np.ndarray = field(repr=False)
    source: np.ndarray = field(repr=False)
    axis_rms: np.ndarray = field(repr=False)
    window_gap: np.ndarray = field(repr=False)
    window_t: np.ndarray = field(repr=False)
    window_source: np.ndarray = field(repr=False)
    vs_rate: np.ndarray = field(repr=False)
    spectrum: tuple = field(repr=False)
    after_reversal: float | None = field(default=None, repr=False)
    elsewhere: float | None = field(default=None, repr=False)
    tilt: tuple | None = field(default=None, repr=False)
    field_vertical: bool | None = field(default=None, repr=False)
    gimbal: tuple | None = field(default=None, repr=False)
    gimbal_busy: tuple | None = field(default=None, repr=False)

    def __str__(self) -> str:
        return "\n".join(self.words)

    def to_json(self) -> dict:
        """Every number (lists) and the sentences; optional entries only when measured."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.default is None:
                continue
            out[f.name] = _jsonable(v)
        return out


def localise(datas, problem: ShootingProblem, fit: Fit, floor: NoiseFloor) -> Localisation:
    """Where the residual of ``fit`` lives, in words and numbers.

    Parameters
    ----------
    datas : sequence of ReplayData
        The logs of the fit.
    problem : ShootingProblem
        The problem ``fit`` solved.
    fit : Fit
        The fit whose residual is localised.
    floor : NoiseFloor
        The noise estimated from the data.

    Returns
    -------
    Localisation
        ``words`` (sentences) and the numbers behind them: ``axis_rms``,
        ``window_gap`` and ``window_t`` (per window), ``vs_rate`` (RMS by quartile of
        |w|), ``after_reversal`` / ``elsewhere``, ``tilt`` (dof 3), ``field_vertical``,
        ``gimbal`` (cmg), ``spectrum`` (frequency, PSD, white-noise level), ``unit``.
    """
    d0 = datas[0]
    unit = d0.gap_unit
    s = primary_series(problem, fit.delta, fit.p)
    res = s["residual"]
    w = problem.windows
    Y = problem.outputs_at(fit.delta, fit.p)[w.weight > 0]
    rate_rows = problem.model.index(list(d0.rate_names), "y")
    rates = s["meas"] if unit == "rad/s" else Y[:, rate_rows]  # gyro, else the model's rate
    if unit == "rad/s":
        axis_floor = floor.rate_axes
        names = d0.rate_names
    else:
        axis_floor = np.full(res.shape[1], floor.attitude)
        names = ("yaw",) if res.shape[1] == 1 else ("attitude x", "attitude y", "attitude z")
    words: list = []
    out: dict = {"residual": res, "rows": s["rows"], "source": s["source"], "unit": unit}
    ratio = _per_axis(out, words, floor.value, axis_floor, names)
    _over_time(out, words, datas, s, w, ratio)
    rmag = np.sqrt(np.sum(res**2, axis=1))
    _against_rate(out, words, rates, rmag, ratio)
    _after_reversals(out, words, d0.dt, s, w, rates, rmag, floor, ratio)
    if d0.q is not None:
        _tilt_and_field(out, words, datas, s, rmag, ratio)
    if d0.testbed.kind == "cmg":
        _gimbals(out, words, datas, s, rmag, ratio)
    _spectrum(out, words, d0.dt, axis_floor, ratio)
    out["words"] = tuple(words)
    return Localisation(**out)


def _series_of(datas, s, pick):
    """``pick(data, row)`` at every residual sample (its log and row)."""
    return np.array([pick(datas[i], r) for i, r in zip(s["source"], s["rows"], strict=True)])


def _per_axis(out, words, sig, axis_floor, names) -> float:
    """The gap against the floor, and the axis the excess is largest on; returns the ratio."""
    res, unit = out["residual"], out["unit"]
    axis_rms = np.sqrt(np.mean(res**2, axis=0))
    out["axis_rms"] = axis_rms
    excess = np.sqrt(np.maximum(axis_rms**2 - axis_floor**2, 0.0))
    gap = _rms(res)
    ratio = gap / max(sig, 1e-300)
    what = "rate" if unit == "rad/s" else "attitude"
    if ratio < ABOVE:
        words.append(
            f"The model replays the logs to the noise floor: gap {gap:.3g} {unit}, "
            f"{ratio:.2f} times the {what} noise {sig:.3g} {unit} estimated from the data."
        )
    else:
        words.append(
            f"The model misses the logs by {gap:.3g} {unit} RMS, {ratio:.1f} times the "
            f"{what} noise {sig:.3g} {unit} estimated from the data."
        )
    if len(names) > 1 and np.max(excess) > 0:
        share = ", ".join(f"{n} {a:.3g}" for n, a in zip(names, axis_rms, strict=True))
        words.append(
            f"Per axis ({unit} RMS): {share}; the excess over the noise is largest on "
            f"{names[int(np.argmax(excess))]}."
        )
    return ratio


def _over_time(out, words, datas, s, w, ratio) -> None:
    """Per window, and within windows (growing with the time since the restart)."""
    res = out["residual"]
    wg = np.array([_rms(res[s["window"] == j]) for j in range(w.n)])
    out["window_gap"] = wg
    out["window_t"] = np.array([datas[w.source[j]].t[w.rows[j, 0]] for j in range(w.n)])
    out["window_source"] = w.source.copy()
    if ratio >= ABOVE and w.n >= 3:
        third = max(w.n // 3, 1)
        first, last = np.nanmean(wg[:third]), np.nanmean(wg[-third:])
        if last > CONTRAST * first:
            words.append("The error grows over the log (later windows miss more).")
        elif first > CONTRAST * last:
            words.append("The error is largest early in the log and shrinks later.")
        else:
            words.append("The error is spread evenly over the log.")
        pos = np.concatenate([np.flatnonzero(w.weight[j] > 0) for j in range(w.n)])
        L = w.length
        early, late = res[pos < L // 4], res[pos >= L - L // 4]
        if late.size and early.size and _rms(late) > CONTRAST * _rms(early):
            words.append(
                "Within each window it grows with the time since the restart: an unmodelled "
                "torque (integrated by the dynamics), not a measurement offset."
            )


def _against_rate(out, words, rates, rmag, ratio) -> None:
    """The error by quarter of the rate magnitude |w|."""
    unit = out["unit"]
    wabs = np.linalg.norm(rates, axis=1)
    qs = np.quantile(wabs, [0.25, 0.5, 0.75])
    bins = np.digitize(wabs, qs)
    vs_rate = np.array([_rms(rmag[bins == b]) for b in range(4)])
    out["vs_rate"] = vs_rate
    if ratio >= ABOVE and vs_rate[3] > CONTRAST * vs_rate[0]:
        words.append(
            f"The error grows with |w|: {vs_rate[3]:.3g} {unit} in the fastest quarter of the "
            f"samples against {vs_rate[0]:.3g} in the slowest."
        )


def _after_reversals(out, words, dt, s, w, rates, rmag, floor, ratio) -> None:
    """The error within 1 s after a rate reversal (of the model or the gyro), and elsewhere."""
    unit = out["unit"]
    after = np.zeros(len(rmag), dtype=bool)
    horizon = max(1, int(round(1.0 / dt)))
    start = 0
    for j in range(w.n):
        m = int((s["window"] == j).sum())
        seg = rates[start : start + m]
        thr = 3 * (floor.rate_axes if floor.rate_axes is not None else np.zeros(seg.shape[1]))
        for a in range(seg.shape[1]):
            sg = np.sign(np.where(np.abs(seg[:, a]) > thr[a], seg[:, a], 0.0))
            nz = np.flatnonzero(sg)
            for k in nz[1:][sg[nz[1:]] != sg[nz[:-1]]]:
                after[start + k : start + min(k + horizon, m)] = True
        start += m
    if after.any() and (~after).any():
        ra, re_ = _rms(rmag[after]), _rms(rmag[~after])
        out["after_reversal"], out["elsewhere"] = ra, re_
        if ratio >= ABOVE and ra > CONTRAST * re_:
            words.append(
                f"It is largest just after a rate reversal ({ra:.3g} {unit} within 1 s of one, "
                f"{re_:.3g} elsewhere): a torque that depends on the sign of w."
            )


def _quartile_rms(x: np.ndarray, rmag: np.ndarray):
    """The quartiles of ``x`` and the RMS error below the first and above the third."""
    q = np.quantile(x, [0.25, 0.75])
    return q, _rms(rmag[x <= q[0]]), _rms(rmag[x >= q[1]])


def _tilt_and_field(out, words, datas, s, rmag, ratio) -> None:
    """dof 3: the error against the tilt, and whether the cage field is vertical."""
    unit, d0 = out["unit"], datas[0]
    q = _series_of(datas, s, lambda d, r: d.q[r])
    tilt = quat.tilt_of(q)
    qt, t_lo, t_hi = _quartile_rms(tilt, rmag)
    out["tilt"] = (float(np.rad2deg(qt[0])), t_lo, float(np.rad2deg(qt[1])), t_hi)
    if ratio >= ABOVE and t_hi > CONTRAST * t_lo:
        words.append(
            f"It grows with the tilt: {t_hi:.3g} {unit} above {np.rad2deg(qt[1]):.0f} deg "
            f"against {t_lo:.3g} below {np.rad2deg(qt[0]):.0f} deg (a gravity torque)."
        )
    if "bx_lab" in d0.u_names:
        idx = [d0.u_names.index(n) for n in ("bx_lab", "by_lab", "bz_lab")]
        b_lab = _series_of(datas, s, lambda d, r: d.u[r, idx])
        if np.any(b_lab != 0):
            vertical = np.allclose(b_lab[:, :2], 0, atol=1e-3 * float(np.abs(b_lab).max()))
            out["field_vertical"] = bool(vertical)
            if vertical:
                words.append(
                    "The cage field is vertical: a torque from a residual dipole cannot be "
                    "told from one of a CM offset in these logs."
                )


def _gimbals(out, words, datas, s, rmag, ratio) -> None:
    """cmg: the error against the gimbal angles and while the gimbals turn fast."""
    unit, d0 = out["unit"], datas[0]
    dm = _series_of(datas, s, lambda d, r: np.mean(np.abs(d.extra_x[r])))
    qd, g_lo, g_hi = _quartile_rms(dm, rmag)
    out["gimbal"] = (float(np.rad2deg(qd[0])), g_lo, float(np.rad2deg(qd[1])), g_hi)
    if ratio >= ABOVE and g_hi > CONTRAST * g_lo:
        words.append(
            f"It is largest when the gimbals are far from zero (mean |delta| above "
            f"{np.rad2deg(qd[1]):.0f} deg: {g_hi:.3g} {unit}, against {g_lo:.3g})."
        )
    cols = [d0.u_names.index(f"dd{i}") for i in range(1, 5)]
    dd = _series_of(datas, s, lambda d, r: d.u[r, cols])
    busy = np.max(np.abs(dd), axis=1) > 0.1 * np.max(np.abs(dd))
    if busy.any() and (~busy).any():
        rb, rq = _rms(rmag[busy]), _rms(rmag[~busy])
        out["gimbal_busy"] = (rb, rq)
        if ratio >= ABOVE and rb > CONTRAST * rq:
            words.append(
                f"It is largest while the gimbals turn fast ({rb:.3g} {unit} against "
                f"{rq:.3g} when they hold): the CMG torque is off by a factor."
            )


def _spectrum(out, words, dt, axis_floor, ratio) -> None:
    """The residual's spectrum against the white noise of the floor: slow or oscillating."""
    res = out["residual"]
    seg = min(256, len(res))
    f, pxx = welch(res, 1.0 / dt, seg)
    white = 2 * dt * axis_floor**2
    out["spectrum"] = (f, pxx, white)
    if ratio >= ABOVE:
        exc = np.maximum(np.sum(pxx, axis=1) - np.sum(white), 0)
        if exc.sum() > 0:
            low = float(exc[f < 0.2].sum() / exc.sum())
            if low > 0.5:
                words.append(
                    f"In frequency the excess error is slow: {100 * low:.0f} % of it below 0.2 Hz "
                    "(a drift or a slowly growing torque)."
                )
            else:
                words.append(
                    f"In frequency the excess error peaks near {float(f[int(np.argmax(exc))]):.2g} "
                    "Hz (the motion's own frequencies: a state-dependent torque)."
                )
