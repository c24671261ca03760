"""Is a balancing run steady over its metrics window? Windowed metrics and a trend test.

The linearised settling time (:mod:`.transient`) misses what the real actuators do: a
slow creep of the integral term through the sliders' backlash can still be lowering the
tilt long after the linear transient has settled. Seed 000 reports its metrics "once the
steady state is reached", so a run is called steady only if the data say so.

The rule. The metrics window is the last third of the run (``W = duration / 3``, the
``metrics_window_s`` of the JSON); the window before it has the same length. Steady means
no material, significant change between the two consecutive windows in

* the measured in-plane gravity ``g_perp^2`` (its mean is ``g_perp_rms^2``), and
* the in-plane stepper positions (the integral state the creep moves).

Consecutive samples are correlated, so the trend is tested on batch means: both windows
are cut into batches of :data:`BATCH_S` and the slope of the batch means against time is
tested (least squares, ``scipy.stats.linregress``). A change is significant at
``p <`` :data:`DRIFT_P` and material when ``g_perp_rms`` changes by more than
:data:`DRIFT_G_REL` or a stepper's mean moves by more than :data:`DRIFT_STEPPER_REL` of its
within-window standard deviation (and more than two steps). A run shorter than six
batches (120 s) is not judged (``steady`` None).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "DRIFT_G_REL",
    "DRIFT_P",
    "DRIFT_STEPPER_REL",
    "BATCH_S",
    "window_drift",
]

#: Significance level of the window-to-window change (two-sided).
DRIFT_P = 0.01
#: Relative change of g_perp_rms between consecutive windows that counts as material: seed
#: 000's two tables differ by 30-40 % for the same method, so 10 % is well inside what
#: the paper resolves and far above the sampling scatter of a 100 s window.
DRIFT_G_REL = 0.10
#: A stepper's mean must move by more than this fraction of its within-window standard
#: deviation, and by more than two steps, to count as a drift: the integral term makes the
#: steppers wander within their noise-driven dither (about one step in 400 s on
#: seed000-tabletop), while a creep through backlash moves them by tens of um.
DRIFT_STEPPER_REL = 1.0
#: s, batch length of the batch-means test: longer than the tilt loop's period (about 17 s
#: on seed000-tabletop, 2 pi sqrt(J / (K_p + k_g))), so the batch means are nearly
#: independent.
BATCH_S = 20.0


def _window_test(y: np.ndarray, n1: int, batch: int) -> tuple[float, float]:
    """Difference of the means of ``y[n1:]`` and ``y[:n1]``, and the two-sided p-value of a
    trend across both windows: ``y`` is cut into batches of ``batch`` samples (longer than
    the samples' correlation, so the batch means are nearly independent) and the slope of
    the batch means against time is tested (``scipy.stats.linregress``)."""
    from scipy import stats  # scipy.stats: 1.2 s CPU to import, loaded only when this runs

    diff = float(np.mean(y[n1:]) - np.mean(y[:n1]))
    nb = y.size // batch
    if nb < 4:
        return diff, 1.0
    means = y[y.size - nb * batch :].reshape(nb, batch).mean(axis=1)
    if np.ptp(means) == 0:
        return diff, 1.0
    return diff, float(stats.linregress(np.arange(nb), means).pvalue)


def window_drift(t, g_perp, steppers, *, step: float = 0.0) -> dict:
    """Windowed metrics of a run's last two thirds and whether they drift.

    Parameters
    ----------
    t : (N,) s
        Sample times.
    g_perp : (N,) -
        Measured in-plane gravity ``|g_hat_xy|``.
    steppers : (N, k) m
        In-plane stepper positions.
    step : float
        m, stepper resolution: a mean shift of two steps or less is not a drift.

    Returns
    -------
    dict
        ``metrics_window_s`` ([start, end], s), ``previous_window_s``, ``g_perp_rms_windows``
        (previous, metrics window), ``stepper_mean_shift_m`` (k), ``drift_p_g``,
        ``drift_p_stepper`` (k), ``steady`` (bool or None when too short) and
        ``steady_reason`` (str).
    """
    t = np.asarray(t, float)
    g = np.asarray(g_perp, float)
    s = np.asarray(steppers, float).reshape(t.size, -1)
    n = t.size
    w = n // 3
    dt = float(t[1] - t[0]) if n > 1 else 1.0
    out: dict = {
        "metrics_window_s": [float(t[n - w]) if w else float(t[0]), float(t[-1] + dt)],
        "previous_window_s": None,
        "g_perp_rms_windows": None,
        "stepper_mean_shift_m": None,
        "drift_p_g": None,
        "drift_p_stepper": None,
        "steady": None,
        "steady_reason": "",
    }
    if 2 * w < 4 * max(1, int(round(BATCH_S / dt))):
        out["steady_reason"] = (
            f"not judged: the trend test needs two windows of at least {2 * BATCH_S:g} s "
            f"(a run of {6 * BATCH_S:g} s or more)"
        )
        return out
    a, b = slice(n - 2 * w, n - w), slice(n - w, n)
    out["previous_window_s"] = [float(t[n - 2 * w]), float(t[n - w])]
    rms = [float(np.sqrt(np.mean(g[a] ** 2))), float(np.sqrt(np.mean(g[b] ** 2)))]
    out["g_perp_rms_windows"] = rms
    batch = max(1, int(round(BATCH_S / dt)))
    span = slice(n - 2 * w, n)
    _, p_g = _window_test(g[span] ** 2, w, batch)
    shifts, p_s, moved = [], [], []
    for j in range(s.shape[1]):
        diff, p = _window_test(s[span, j], w, batch)
        sd = max(float(np.std(s[a, j])), float(np.std(s[b, j])))
        shifts.append(diff)
        p_s.append(p)
        moved.append(p < DRIFT_P and abs(diff) > max(DRIFT_STEPPER_REL * sd, 2 * step))
    out.update(stepper_mean_shift_m=shifts, drift_p_g=p_g, drift_p_stepper=p_s)
    rel = abs(rms[1] - rms[0]) / max(rms[0], 1e-300)
    reasons = []
    if p_g < DRIFT_P and rel > DRIFT_G_REL:
        reasons.append(
            f"g_perp_rms went from {rms[0]:.3g} ({out['previous_window_s'][0]:.0f}-"
            f"{out['previous_window_s'][1]:.0f} s) to {rms[1]:.3g} in the metrics window "
            f"({100 * rel:.0f} %, p = {p_g:.1g})"
        )
    for j, m in enumerate(moved):
        if m:
            reasons.append(
                f"stepper {j + 1}'s mean moved {shifts[j] * 1e6:+.1f} um between the windows "
                f"(p = {p_s[j]:.1g})"
            )
    out["steady"] = not reasons
    out["steady_reason"] = (
        "drifting: " + "; ".join(reasons)
        if reasons
        else f"no significant change between two consecutive {w * dt:.0f} s windows "
        f"(g_perp_rms within {100 * DRIFT_G_REL:.0f} % or p >= {DRIFT_P})"
    )
    return out
