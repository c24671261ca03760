"""Quality of a log: segments, jitter and outliers (FORMATS.md, "Real logs are not perfect").

:func:`assess` says, for one log and its testbed, which rows form segments (runs of
samples between gaps), how irregular the sampling is, and which rows are
**outliers**: isolated samples that no smooth motion explains. Every tool leaves the
outlier rows out of its fits (``Log.usable_mask()``) and reports them by row (0-based
data rows, the same in a raw file and its imported log).

This module holds :func:`assess` (the front door) and the rule's text below; the work is
in the modules under it, and every name a user imports from here still is importable
from here:

- :mod:`airbearing.io.quality_result`: :class:`LogQuality` and :class:`Outlier`;
- :mod:`airbearing.io.quality_channels`: the channel groups of a log (step 1, the scale
  floors, the inputs) and the rows near a command's switch;
- :mod:`airbearing.io.quality_outliers`: the rule on one group (steps 2 to 7):
  ``_Scorer``, :func:`find_outliers`; its numerics in :mod:`airbearing.io.local_fits`;
- :mod:`airbearing.io.quality_edges`: the rule at a segment's ends (step 3: each edge
  row's fit and its edge factor, the white-noise tests at ``EDGE_LEVEL``);
- :mod:`airbearing.io.discontinuity` (steps), :mod:`airbearing.io.gyro_check` (the gyro
  against the attitude), :mod:`airbearing.io.motion` (still channels, no motion).

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
   (unwrapped within the segment, an isolated jump keeping the branch). The wheel
   speeds ``ws1..wsn`` of a reaction-wheel testbed, each on its own, with the noise
   floor ``wheels.speed_noise`` (a switch of a command ``wc`` is a kink as below). The input
   channels too (see "Inputs" below): the gimbal angles ``d1..d4``, the sliders
   ``s1..s3`` and the dipoles ``mx..mz``, each channel on its own.
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
   (5, 6) and the most sensitive one is used: the one whose robust scale (step 4)
   times ``sqrt(1 + h)`` (``h`` on a regular grid: 0.50, 0.72, 0.91) is smallest, i.e.
   which flags the smallest glitch. Under pure noise the normalised scales agree and
   the low degree wins (smaller ``h``); when the motion is fast for the sample rate
   (a 4 rad/s spin at 10 Hz, a 1.6 rad/s oscillation at 20 Hz) the low degree leaves
   a curvature residual and a higher degree, whose bias falls as
   ``(omega dt)^(p+2)``, removes it. So the scale measures the noise, not the
   model's curvature. The first and last ``k`` samples
   of a segment are extrapolated, where a fit's misfit is larger: each window shape
   (how many neighbours on the left) has its own scale, measured on the log itself
   by predicting every sample with that shape. A motion may also change fastest where
   the log begins (a logged estimate's filter starting with the log), which the
   log-wide scale does not see: the same fit and shape predict the ``2k`` rows
   inwards from windows without the row, and where their residuals fail a test of
   white noise at :data:`~airbearing.io.quality_edges.EDGE_LEVEL` (their sum, which
   a misfit makes of one sign, and their sum of squares, each against its
   distribution under the residuals' correlation), their root mean square is the
   edge's factor on the scale (never below 1). Each row near a segment's end uses
   the fit whose scale times that factor times ``sqrt(1 + h)`` is smallest there;
   none of it depends on the row's own sample.
4. **Robust noise scale**, per channel over all segments: ``1.4826 * MAD`` of the
   normalised residuals (for the quaternion, ``sqrt(median(|r|^2) / 2.366)``, the
   median of chi-square with 3 degrees of freedom: attitude noise of ``sigma`` rad
   per axis moves the unit quaternion by ``sigma / 2`` per tangent axis, so
   ``|r|^2`` is chi-square(3) whatever the attitude, while single components are
   not identically distributed). The scale is never taken below the testbed's
   nominal noise (``sensors.gyro_noise``; ``sensors.attitude_noise``, halved for the
   quaternion) nor below :data:`ABSOLUTE_FLOOR` = 1e-7 rad or rad/s (quieter than
   any real sensor) or ``1e-9`` of the channel's magnitude, so that a noise-free
   simulated log is judged against a physical noise, not the fits' own rounding.
   Where the log is locally rougher than overall (a running median of the squared
   normalised residuals over 51 samples), the local scale is used. A channel with
   no noise at all (a simulation: its scale at the floor) cannot tell a glitch from
   a kink (a torque switched, a rate limit reached) by statistics; its scale is
   never below 0.2 x the running median of its |second difference| (the motion's
   own change of slope per sample), which real sensor noise always exceeds.
5. **Threshold.** A sample is suspect when a channel's normalised residual exceeds
   6 scales (two-sided Gaussian tail 2e-9; for the quaternion, ``|r|^2`` above
   chi-square(3) at 2e-9, i.e. 43.4 squared scales). With 3 rate channels and the
   attitude on 10^5 samples the expected number of false flags on a clean log is
   ``10^5 * 4 * 2e-9 ~ 1e-3``. A real glitch of 20 noise scales gives a normalised
   residual of about 20 / sqrt(1.5) = 16 in the interior and still above 6 at a
   segment's end.
6. **Masking, one glitch at a time.** A glitch also pulls the fits of its
   neighbours, so only the suspects that are the largest within ``k`` samples are
   taken; around such a suspect, the row or pair of consecutive rows whose exclusion
   best explains the neighbourhood (smallest sum of squared scores left, plus the
   threshold squared per excluded row) is left out: a glitch at a segment's first
   sample pulls the second sample's interior fit harder than its own extrapolated
   one, and two consecutive glitches pull each other. The residuals near them are
   computed again and this repeats
   until no new suspect remains. A sample is an outlier if its final residual (its
   neighbours' outliers left out) is still above the threshold.
7. **Isolated only.** A run of 1 or 2 consecutive suspects is an outlier run. A run
   of 3 or more is not an isolated glitch but something the log really did (an
   impact, a sustained fault, a step): it is reported as ``unexplained`` and kept
   in the fits (nothing is silently dropped).

Noise-free first-sample artefacts (a rate of 0 at a segment's first sample because
the exporter differentiated the attitude) are found by the extrapolated fit of
step 2: the residual is the whole rate, many noise scales unless the platform is
at rest, in which case 0 is not wrong.

Inputs
------
Gimbal angles, slider positions and dipoles get the same rule, with two changes
that their physics asks for:

- **Commands switch between samples.** A commanded rate or dipole may step, and a
  stepper slider starts and stops at once, so an input is smooth only piecewise: a
  kink or a step is not a glitch. Each input sample is therefore scored by the best
  of three fits of the same ``(k, p)``: the centred one (steps 2-4) and the two
  one-sided ones (all ``2k`` neighbours before it, all after it), each against its
  own scale measured on the log. A kink or step leaves one side straight, which
  explains the sample; a glitch disagrees with both sides. A sample with fewer than
  ``2k`` samples of its segment on one side has no one-sided fit there: a command
  may have switched just beyond it (a controller starting with the segment), so it
  is not judged. Channels that do not change within any segment are not tested
  (nothing to find, nothing to pay).
- **Gimbal angles follow their commanded rates.** They are tested when the log has
  ``dd1..dd4``: the rule is applied to ``d_i - D_i``, with ``D_i`` the zero-order-
  hold integral of the logged commanded rate from the segment's first sample. What
  is left is the tracking error (dead zone, rate limit, encoder noise), smooth even
  in a fast slew, so a glitch of a fraction of a degree stands out at its own row.
  Without the commanded rates the angles are the only record of the command, and a
  steering law that chatters near a singularity (the gimbals stepping back and forth
  every sample) cannot be told from glitches: they are not tested.

The platform answers a command that switches: its rate has a kink there and its attitude
a change of curvature, which a centred fit cannot follow either. Rows within ``k`` of a
switch of a logged command (a commanded gimbal rate or dipole whose change between two
samples exceeds :data:`SWITCH_RATIO` times its median change; a slider whose speed does)
are therefore scored by the best of the centred and one-sided fits on the rates and the
yaw (not the quaternion, whose chi-square test takes no side per channel). The motion may
change its character there (a rate limit reached and left at once), so each side takes
the first fit of :data:`FITS`, in order of degree, that explains that side's next sample:
the lowest degree that follows the motion, chosen without the tested row, so a glitch
cannot choose the fit that hides it. A one-sided fit needs its ``2k`` neighbours
unbroken, so a glitch right beside a switch may take one neighbour with it.

Scale floors: sliders at ``masses.step`` (a stepper position moves in whole steps: a
slow move is a staircase whose misfit from a smooth curve reaches a step or two,
not random rounding of ``step / sqrt(12)``), others at :data:`ABSOLUTE_FLOOR` and
``1e-9`` of the channel's magnitude; a noise-free simulated input then falls back on
the change-of-slope floor of step 4.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from airbearing.errors import InputError
from airbearing.io.columns import segments_of, time_text
from airbearing.io.discontinuity import (  # noqa: F401 (RowFinding: re-exported)
    CHI2_3_THRESHOLD,
    Z_THRESHOLD,
    Discontinuity,
    RowFinding,
    find_steps,
    rate_changes,
    split_at,
)
from airbearing.io.gyro_check import gyro_disagreement
from airbearing.io.motion import no_motion, still_channels
from airbearing.io.quality_channels import (  # noqa: F401 (re-exported: the quality module's names)
    SWITCH_RATIO,
    _groups,
    _switch_rows,
)
from airbearing.io.quality_outliers import (  # noqa: F401 (re-exported: the quality module's names)
    ABSOLUTE_FLOOR,
    FITS,
    _Group,
    _normalised,
    _Scorer,
    find_outliers,
)
from airbearing.io.quality_result import INPUT_COLUMNS, LogQuality, Outlier  # noqa: F401 (re-exported)
from airbearing.io.testbed import Testbed

if TYPE_CHECKING:
    from airbearing.io.log import Log

__all__ = [
    "CHI2_3_THRESHOLD",
    "FITS",
    "Outlier",
    "LogQuality",
    "Z_THRESHOLD",
    "assess",
    "find_outliers",
]

# Z_THRESHOLD, CHI2_3_THRESHOLD and RowFinding are defined in io.discontinuity (which
# the step detector shares with this rule) and exported from here too; so are the names
# of io.quality_result, io.quality_outliers and io.quality_channels used elsewhere.


_WHAT = {"rates": "rate", "gimbals": "gimbal angle", "sliders": "slider", "dipoles": "dipole"}
_WHAT["wheel_speeds"] = "wheel speed"


def _reason(group: _Group, cols: tuple[str, ...], score: float, logged_zero: bool) -> str:
    what = _WHAT.get(group.name, "attitude")
    return (
        f"{what} {', '.join(cols)}{' logged as 0,' if logged_zero else ''} {score:.3g} noise "
        "scales from the smooth fit of its neighbours"
    )


def assess(log: Log, testbed: Testbed | None) -> LogQuality:
    """Segments, jitter and outliers of a log (the rule is in the module docstring).

    Parameters
    ----------
    log : Log
        A validated log (``read_log``, ``Log(...)``); its columns are read as they are.
    testbed : Testbed or None
        Its sample rate defines gaps (interval > 1.5 / rate) and jitter; its sensors
        say which columns are measurements (``sensors.gyro``) and give the noise
        floors (``gyro_noise``, ``attitude_noise``). Without one (``log import``
        without ``--testbed``) the period is the median interval, the rates and the
        attitude are tested when present, and there is no nominal noise floor.

    Returns
    -------
    LogQuality

    Raises
    ------
    InputError
        If ``testbed`` is not a Testbed.
    """
    if testbed is not None and not isinstance(testbed, Testbed):
        raise InputError(f"{log.source}: assess needs a Testbed, got {type(testbed).__name__}")
    t = log.t
    n = t.size
    period = testbed.sensors.dt if testbed is not None else float(np.median(np.diff(t)))
    segments = segments_of(t, period)
    groups, scorers, steps = _steps(log, testbed, segments, t, period)
    if steps:  # a step breaks the segment there as a gap does (nothing filled)
        segments = split_at(segments, [s.row for s in steps])
        switch = _switch_rows(log, segments, max(k for k, _ in FITS))
        groups, scorers = _groups(log, testbed, segments, switch), {}
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
    for group in groups:
        res = find_outliers(group, t, segments, period, scorers.get(group.name))
        fits[group.name] = res.fit
        if group.vector:
            noise["quaternion"] = float(res.noise[0])
        else:
            noise.update({c: float(v) for c, v in zip(group.columns, res.noise, strict=True)})
        unexplained |= res.unexplained
        for i in (int(i) for i in np.flatnonzero(res.flagged)):
            cols = tuple(c for c, o in zip(group.columns, res.over[i], strict=True) if o)
            cols = cols or group.columns
            zero = all(float(log._values(c)[i]) == 0 for c in cols)
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
    usable = np.ones(n, dtype=bool)
    usable[[o.row for o in outliers]] = False
    disagree = ()
    if log.rates() is not None and (noise.get("yaw") or noise.get("quaternion")):
        att_noise = noise.get("yaw") or noise["quaternion"]
        disagree = gyro_disagreement(log, segments, usable, att_noise)
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
        gyro_disagreement=disagree,
        noise_warnings=_noise_warnings(noise, testbed),
        discontinuities=steps,
        rate_changes=() if testbed is None else rate_changes(t, period, testbed.sensors.rate),
        **_motion(log, testbed, segments),
    )


def _motion(log: Log, testbed, segments) -> dict:
    """``still_channels`` and ``no_motion`` (:mod:`airbearing.io.motion`)."""
    return {
        "still_channels": still_channels(log, testbed, segments),
        "no_motion": no_motion(log, testbed),
    }


def _steps(log: Log, testbed, segments, t, period):
    """The channel groups, the scorers of the rates and attitude, and the steps found
    on them (:mod:`airbearing.io.discontinuity`), merged by row."""
    switch = _switch_rows(log, segments, max(k for k, _ in FITS))
    groups = _groups(log, testbed, segments, switch)
    scorers: dict[str, _Scorer] = {}
    found: dict[int, tuple[list[str], float]] = {}
    for g in groups:
        if g.name not in ("rates", "attitude"):
            continue
        scorer = scorers[g.name] = _Scorer(g, t, segments, period)
        for row, cols, score in find_steps(scorer, t, period, switch):
            have = found.setdefault(row, ([], 0.0))
            found[row] = (have[0] + list(cols), max(have[1], score))
    steps = tuple(
        Discontinuity(
            row=r,
            t=float(t[r]),
            columns=tuple(cols),
            reason=(
                f"step between rows {r - 1} and {r} (t = {time_text(t[r - 1], period)} .. "
                f"{time_text(t[r], period)} s): "
                f"{', '.join(cols)} {score:.3g} noise scales apart where the smooth fits "
                "of each side meet (two runs joined? samples cut out?): a new segment starts"
            ),
            score=score,
        )
        for r, (cols, score) in sorted(found.items())
    )
    return groups, scorers, steps


#: A channel whose noise exceeds the testbed's declared one this many times is named.
NOISE_RATIO = 10.0


def _noise_warnings(noise: dict, testbed) -> tuple[str, ...]:
    """Channels far noisier than the testbed says its sensors are (the module docstring)."""
    if testbed is None:
        return ()
    s = testbed.sensors
    declared = {c: (s.gyro_noise, "gyro_noise", "rad/s") for c in ("wx", "wy", "wz")}
    declared |= {c: (s.attitude_noise, "attitude_noise", "rad") for c in ("yaw", "quaternion")}
    if testbed.wheels is not None:  # the wheel speeds: wheels.speed_noise
        sigma = testbed.wheels.speed_noise
        declared |= {f"ws{i}": (sigma, "speed_noise", "rad/s") for i in range(1, 7)}
    out = []
    for ch, value in noise.items():
        ref, key, unit = declared.get(ch, (0.0, "", ""))
        if ref > 0 and value > NOISE_RATIO * ref:
            out.append(
                f"{ch} noise {value:.3g} {unit} is {value / ref:.3g} x the testbed's "
                f"{'wheels' if key == 'speed_noise' else 'sensors'}.{key} {ref:.3g} {unit} "
                "(a unit read wrong, e.g. deg as rad? the "
                "wrong testbed?)"
            )
    return tuple(out)
