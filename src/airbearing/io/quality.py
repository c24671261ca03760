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
   by predicting every sample with that shape, and each position near a segment's
   end uses the fit whose scale there is smallest.
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

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from airbearing.errors import InputError
from airbearing.io.columns import (
    _DIPOLES,
    _GIMBAL_RATES,
    _GIMBALS,
    _SLIDERS,
    WHEEL_COMMAND_COLUMNS,
    segments_of,
    time_text,
)
from airbearing.io.discontinuity import (
    _CHI2_3_MEDIAN,
    _MAD_TO_SIGMA,
    CHI2_3_THRESHOLD,
    Z_THRESHOLD,
    Discontinuity,
    RowFinding,
    find_steps,
    poly_weights,
    rate_changes,
    split_at,
)
from airbearing.io.gyro_check import gyro_disagreement
from airbearing.io.import_map import unwrap
from airbearing.io.local_fits import LOCAL as _LOCAL
from airbearing.io.local_fits import REGULAR_ULPS as _REGULAR_ULPS
from airbearing.io.local_fits import loo as _loo_regular
from airbearing.io.local_fits import noise_gain as _noise_gain
from airbearing.io.local_fits import regular_span as _regular_span
from airbearing.io.local_fits import regular_weights as _regular_weights
from airbearing.io.local_fits import window_median as _window_median
from airbearing.io.local_fits import window_shape as _window_shape
from airbearing.io.motion import no_motion, still_channels
from airbearing.io.testbed import Sensors, Testbed
from airbearing.quaternion import continuous_signs

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

# Z_THRESHOLD, CHI2_3_THRESHOLD and RowFinding are defined in io.discontinuity (which
# the step detector shares with this rule) and exported from here too.
#: The local fits tried, ``(k, p)``: k samples each side, polynomial degree p.
FITS: tuple[tuple[int, int], ...] = ((3, 2), (4, 4), (5, 6))
_MAX_RUN = 2  # longest run of consecutive suspects that is an isolated glitch
_RELATIVE_FLOOR = 1e-9  # scale floor relative to the channel's magnitude
#: rad or rad/s: no scale below this. A star tracker's 1 arcsec is 5e-6 rad and a
#: navigation-grade gyro has ~1e-6 rad/s of noise per sample at 20 Hz, so no real
#: sensor is this quiet; a noise-free simulated log is judged against it, not
#: against the local fits' own rounding and misfit.
ABSOLUTE_FLOOR = 1e-7
#: Log columns that models take as inputs: a glitch in one breaks the segment there
#: (:meth:`LogQuality.input_segments`).
INPUT_COLUMNS = frozenset(
    ("d1", "d2", "d3", "d4", "dd1", "dd2", "dd3", "dd4", "s1", "s2", "s3", "mx", "my", "mz")
    + ("bx", "by", "bz")
)
_MAX_PASSES = 200
_SCALE_ROWS = 2000  # rows spread over the log on which the noise scales are measured
_MIN_SCALE_SAMPLES = 8  # fewer residuals than this give no scale (the floor is used)
_RECOMPUTE = 3  # rows within this many k of a newly excluded sample are refitted
_ROUGH = 0.2  # noise-free channels: scale floor per unit median |second difference|


@dataclass(frozen=True)
class Outlier(RowFinding):
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
        interval longer than 1.5 periods, or a step (:attr:`discontinuities`).
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
        ``"attitude"``, and the inputs tested: ``"gimbals"``, ``"sliders"``,
        ``"dipoles"``; their channels' scales are in ``noise``, a gimbal angle's
        as ``d - D``, module doc).
    unchecked_rows : tuple of int
        Rows of segments too short for any local fit (fewer than 4 samples).
    gyro_disagreement : tuple of str
        Why the gyro and the logged attitude disagree (a dead, reversed, mis-scaled or
        saturated axis: :mod:`airbearing.io.gyro_check`), empty when they agree; no fit
        takes such a log.
    noise_warnings : tuple of str
        Channels whose noise is more than :data:`NOISE_RATIO` times the testbed's
        ``gyro_noise`` or ``attitude_noise`` (a unit read wrong, the wrong testbed).
    discontinuities : tuple of airbearing.io.discontinuity.Discontinuity
        Steps no smooth motion explains (two runs joined, samples cut out): a segment
        ends before each one's row and the next starts at it, as at a gap.
    rate_changes : tuple of dict
        Stretches sampled at another rate than ``sensors.rate``
        (:func:`airbearing.io.discontinuity.rate_changes`).
    still_channels : tuple of str
        Channels far quieter than the testbed's declared noise: frozen or noise-free
        (:func:`airbearing.io.motion.still_channels`).
    no_motion : str
        Why the log shows no motion (:func:`airbearing.io.motion.no_motion`), or ``""``.

    Examples
    --------
    A 3 s simulated log with five rows (0.25 s) taken out, read as a gap:

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> log = ab.slew(tb, angle_deg=30.0, duration=3.0, seed=1).log
    >>> quality = ab.Log(log.data.drop(index=range(20, 25)), testbed=tb).quality
    >>> quality.n_rows, quality.segments, round(quality.period, 3)  # rows, row ranges, s
    (55, ((0, 20), (20, 55)), 0.05)
    >>> quality.findings()
    (('outlier rows', 'none'),)
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
    gyro_disagreement: tuple[str, ...] = ()
    noise_warnings: tuple[str, ...] = ()
    discontinuities: tuple = ()
    rate_changes: tuple[dict, ...] = ()
    still_channels: tuple[str, ...] = ()
    no_motion: str = ""

    @property
    def n_segments(self) -> int:
        """Number of segments."""
        return len(self.segments)

    def findings(self, shown_rows: int = 20) -> tuple[tuple[str, str], ...]:
        """What the check found besides the segments, in words: ``(what, text)`` pairs.

        The one text of ``log import``'s summary and the log plot's page: each step, each
        change of sampling rate, the outlier rows (the first ``shown_rows`` and how many in
        all) and each channel that is quieter than the testbed says.

        Parameters
        ----------
        shown_rows : int
            Outlier rows listed before ``... (N in all)``.

        Returns
        -------
        tuple of (str, str)
            ``("discontinuity", "row 532: ...")``, ``("rate change", ...)``,
            ``("outlier rows", "400, 1700")`` (``"none"`` when there are none),
            ``("still", ...)``, in that order.
        """
        out = [("discontinuity", f"row {d.row}: {d.reason}") for d in self.discontinuities]
        out += [("rate change", str(change["reason"])) for change in self.rate_changes]
        rows = list(self.outlier_rows)
        text = ", ".join(str(r) for r in rows[:shown_rows]) or "none"
        if len(rows) > shown_rows:
            text += f", ... ({len(rows)} in all)"
        out.append(("outlier rows", text))
        out += [("still", warning) for warning in self.still_channels]
        return tuple(out)

    @property
    def input_rows(self) -> tuple[int, ...]:
        """Outlier rows with a bad input column (:data:`INPUT_COLUMNS`), sorted."""
        return tuple(sorted(o.row for o in self.outliers if INPUT_COLUMNS & set(o.columns)))

    def input_segments(self) -> tuple[tuple[int, int], ...]:
        """The segments broken at every :attr:`input_rows` row (stop exclusive).

        A bad input is not a bad measurement: leaving its row out of a residual would still
        integrate a model through it (held over its interval, or as the difference that
        derives a gimbal rate). So a segment ends before the row and the next starts after
        it; nothing is filled.

        Returns
        -------
        tuple of (int, int)
            ``(start, stop)`` row ranges, 0-based.
        """
        bad = self.input_rows
        out = []
        for a, b in self.segments:
            start = a
            for g in (r for r in bad if a <= r < b):
                if g > start:
                    out.append((start, g))
                start = g + 1
            if start < b:
                out.append((start, b))
        return tuple(out)

    def usable_mask(self) -> np.ndarray:
        """True for every row a fit may use (False at outlier rows).

        Returns
        -------
        numpy.ndarray
            Shape (n_rows,), bool.
        """
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
            ``unexplained_rows``, ``unchecked_rows``, ``noise`` (per channel),
            ``fits`` (per group, ``[k, p]``) and ``gyro_disagreement`` (sentences).
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
            "gyro_disagreement": list(self.gyro_disagreement),
            "noise_warnings": list(self.noise_warnings),
            "discontinuity_rows": [d.row for d in self.discontinuities],
            "discontinuities": [d.to_json() for d in self.discontinuities],
            "rate_changes": [dict(r) for r in self.rate_changes],
            "still_channels": list(self.still_channels),
            "no_motion": self.no_motion,
        }


@dataclass
class _Group:
    name: str  # "rates", "attitude" or an input group ("gimbals", "sliders", "dipoles")
    columns: tuple[str, ...]  # log columns
    values: np.ndarray  # (n, c), prepared (signs continuous, yaw unwrapped)
    vector: bool  # True: one chi-square(3) test on the vector (quaternion)
    floor: np.ndarray  # (c,) or (1,) scale floor
    wrap: bool = False  # residual modulo 2 pi (yaw)
    sided: bool = False  # inputs: the best of the centred and one-sided fits (module doc)
    # rows next to a command's switch: the best of the three fits there too (module doc)
    switch_rows: np.ndarray | None = None


def _loo(t, x, good, k, p, scale, rows, shape=None):
    """`local_fits.loo` (the parameters and returns are its own), with the windows that
    are complete (``2k`` neighbours, all good) but not regular (a jittered clock) fitted
    all at once (:func:`airbearing.io.discontinuity.poly_weights`) instead of one Gram
    solve per row: the same least-squares prediction, equal to its rounding."""
    a, b = _window_shape(t.size, k, rows, shape)
    full = (a + b) == 2 * k
    cand = np.flatnonzero(full & ~_regular_span(t, good, rows, a, b, k)) if full.any() else ()
    del b, full
    if len(cand) == 0:  # (without this call's arrays: a long log's peak memory)
        del a
        return _loo_regular(t, x, good, k, p, scale, rows, shape)
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
    first = np.where(fits, rows - shapes, rows)  # (shapes, rows): first row of each span
    span = np.minimum(first[..., None] + np.arange(2 * k + 1), t.size - 1)
    dt = np.diff(t[span], axis=-1)
    big = np.maximum(np.abs(t[lo]), np.abs(t[hi - 1]))
    tol = _REGULAR_ULPS * np.spacing(big)
    regular = fits & (np.max(dt, axis=-1) - np.min(dt, axis=-1) <= tol)
    x = group.values
    for a in range(n_shapes):
        at = rows[regular[a]]
        if at.size:
            w = _regular_weights(k, p, a)
            offsets = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)]
            pred = w[0] * x[at + offsets[0]]  # as _loo's fast path
            for off, wj in zip(offsets[1:], w[1:], strict=True):
                pred += wj * x[at + off]
            r = x[at] - pred
            if group.wrap:
                r = np.mod(r + np.pi, 2 * np.pi) - np.pi
            out[a, regular[a]] = r / np.sqrt(1.0 + float(w @ w))
        other = np.flatnonzero(fits[a] & ~regular[a])
        if other.size:  # jittered windows: the least-squares weights of each, all at once
            at = rows[other]
            offsets = np.r_[-np.arange(a, 0, -1), np.arange(1, 2 * k - a + 1)]
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
        z2 = np.sum(d * d, axis=1) / s[:, 0] ** 2
        over = np.repeat((z2 > CHI2_3_THRESHOLD)[:, None], d.shape[1], axis=1)
        return np.sqrt(z2), over
    z = np.abs(d) / s
    return np.max(z, axis=1), z > Z_THRESHOLD


class _Scorer:
    """Normalised scores of rows under the local fit chosen for each row's position.

    Interior rows use the fit whose interior scale is smallest (module docstring,
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
            return float(np.sum(np.log(s)) + s.size * 0.5 * np.log1p(_noise_gain(*f, a)))

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
            self._rough_sq = np.sum(d**2, axis=1, keepdims=True) / _CHI2_3_MEDIAN
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
        sample best, in its own scale (module doc, "Inputs").

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
                # no one-sided fit (too near the segment's end): not judged (module doc)
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
        edge_rows = np.flatnonzero(
            np.minimum(self.from_start[rows], self.from_end[rows]) < self._edge_depth
        )
        from_start, from_end = self.from_start[rows[edge_rows]], self.from_end[rows[edge_rows]]
        for (side, e), (kf, pf) in self.edge.items():
            at = (from_start if side == 0 else from_end) == e
            at &= (from_end if side == 0 else from_start) >= kf
            if not at.any():
                continue
            at = edge_rows[at]
            d_f, shapes_f = _normalised(g, t, segs, good, kf, pf, sc, rows[at])
            d[at], scale[at] = d_f, self.scales[(kf, pf)][np.clip(shapes_f, 0, 2 * kf)]
        if g.sided:
            d, scale = self._sided(rows, good, d, scale)
        elif g.switch_rows is not None:
            at = np.flatnonzero(g.switch_rows[rows])
            if at.size:
                # the motion changes its character at a switch (a rate limit reached
                # or left): every fit's one-sided form, the higher degrees follow it
                d[at], scale[at] = self._sided(rows[at], good, d[at], scale[at], FITS)
        if exact:
            return _score(g, d, scale * self.local_at(rows))
        score, over = _score(g, d, scale)  # local factor 1: an upper bound of each score
        maybe = over.any(axis=1)
        if maybe.any():
            score[maybe], over[maybe] = _score(
                g, d[maybe], scale[maybe] * self.local_at(rows[maybe])
            )
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
    """Run the rule of the module docstring on one channel group (``scorer``: the group's,
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
        suspect = over.any(axis=1) & ~excluded
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
    suspect = excluded & over.any(axis=1)
    flagged = np.zeros(n, dtype=bool)
    unexplained = np.zeros(n, dtype=bool)
    bad = np.flatnonzero(suspect)
    if bad.size:
        breaks = np.flatnonzero((np.diff(bad) != 1) | (np.diff(seg_id[bad]) != 0)) + 1
        for run in np.split(bad, breaks):
            (flagged if run.size <= _MAX_RUN else unexplained)[run] = True
    return _GroupResult(flagged, unexplained, score, over, scorer.noise, scorer.fit)


# ----------------------------------------------------------------------------
# channel groups of a log


def _groups(log: Log, testbed: Testbed | None, segments, switch: np.ndarray | None) -> list[_Group]:
    """The channel groups of a log; ``switch``: :func:`_switch_rows` on the same segments."""
    t = log.data["t"].to_numpy(dtype=float)
    groups = []
    sensors = testbed.sensors if testbed is not None else Sensors(gyro_noise=0.0)
    rates = log.rates()
    if rates is not None:
        cols = ("wx", "wy", "wz") if rates.shape[1] == 3 else ("wz",)
        mag = np.maximum(np.max(np.abs(rates), axis=0), 1.0)
        floor = np.maximum(max(sensors.gyro_noise, ABSOLUTE_FLOOR), _RELATIVE_FLOOR * mag)
        groups.append(_Group("rates", cols, rates, False, floor))
    speeds = log.wheel_speeds()
    if speeds is not None:  # measured like the rates, with the wheels' own noise
        wheels = testbed.wheels if testbed is not None else None
        cols = tuple(f"ws{i}" for i in range(1, speeds.shape[1] + 1))
        mag = np.maximum(np.max(np.abs(speeds), axis=0), 1.0)
        sigma = wheels.speed_noise if wheels is not None else 0.0
        floor = np.maximum(max(sigma, ABSOLUTE_FLOOR), _RELATIVE_FLOOR * mag)
        groups.append(_Group("wheel_speeds", cols, speeds, False, floor))
    dof = testbed.body.dof if testbed is not None else (3 if log.has("qw") else 1)
    use_yaw = dof == 1 and log.has("yaw")
    if use_yaw:
        yaw = log.column("yaw")
        for start, stop in segments:  # a logged yaw should be unwrapped; if not, this does
            yaw[start:stop] = unwrap(yaw[start:stop], t[start:stop])
        mag = max(float(np.max(np.abs(yaw))), 1.0)
        floor = np.array([max(sensors.attitude_noise, ABSOLUTE_FLOOR, _RELATIVE_FLOOR * mag)])
        groups.append(_Group("attitude", ("yaw",), yaw[:, None], False, floor, wrap=True))
    elif log.has("qw", "qx", "qy", "qz"):
        q = continuous_signs(log.quaternions(), segments)
        floor = np.array([0.5 * max(sensors.attitude_noise, ABSOLUTE_FLOOR)])
        groups.append(_Group("attitude", ("qw", "qx", "qy", "qz"), q, True, floor))
    if switch is not None:
        for g in groups:  # (a quaternion's chi-square test takes no per-channel side)
            g.switch_rows = None if g.vector else switch
    groups += _input_groups(log, testbed, segments, t)
    return groups


#: A command switches where its change between two samples exceeds this many times its
#: median change (a reference step, a bang-bang switch, a stepper starting or stopping).
SWITCH_RATIO = 20.0


def _switch_rows(log: Log, segments, k: int) -> np.ndarray | None:
    """Rows within ``k`` of a switch of a logged command (module doc, "Inputs"), or None.

    Commanded gimbal rates and dipoles switch where they step; slider positions where
    their speed does (a stepper starting or stopping). The platform's response has a kink
    there (its rate) or a change of curvature (its attitude), which a centred smooth fit
    cannot follow.
    """
    n = len(log.data)
    out = np.zeros(n, dtype=bool)

    wc = tuple(c for c in WHEEL_COMMAND_COLUMNS if c in log.data.columns)
    for cols, order in ((_GIMBAL_RATES, 1), (_DIPOLES, 1), (_SLIDERS, 2), (wc, 1)):
        if not cols:
            continue
        if not log.has(*cols):
            continue
        u = np.stack([log.column(c) for c in cols], axis=1).astype(float)
        tiny = 1e-12 * np.max(np.abs(u), axis=0)  # once per log, not per segment
        for start, stop in segments:
            if stop - start <= order + 1:
                continue
            du = np.abs(np.diff(u[start:stop], order, axis=0))
            typical = np.median(du, axis=0)
            big = du > SWITCH_RATIO * np.maximum(typical, tiny)
            for j in np.flatnonzero(big.any(axis=1)) + start + order:
                out[max(j - k, start) : min(j + k + 1, stop)] = True
    return out if out.any() else None


def _changing(values: np.ndarray, segments) -> np.ndarray:
    """Per channel: does it change within some segment of at least 4 samples?"""
    out = np.zeros(values.shape[1], dtype=bool)
    for start, stop in segments:
        if stop - start >= 4:
            out |= np.ptp(values[start:stop], axis=0) > 0
    return out


def _input_groups(log: Log, testbed: Testbed | None, segments, t: np.ndarray) -> list[_Group]:
    """Gimbal angles (minus the integral of their commanded rates), sliders and dipoles."""
    groups = []
    step = 0.0
    if testbed is not None and getattr(testbed, "masses", None) is not None:
        step = float(testbed.masses.step)  # whole steps (module doc, "Inputs")
    for name, cols, floor in (
        ("gimbals", _GIMBALS, ABSOLUTE_FLOOR),
        ("sliders", _SLIDERS, max(step, ABSOLUTE_FLOOR)),
        ("dipoles", _DIPOLES, ABSOLUTE_FLOOR),
    ):
        if not log.has(*cols):
            continue
        x = np.stack([log.column(c) for c in cols], axis=1).astype(float)
        if name == "gimbals":
            if not log.has(*_GIMBAL_RATES):
                continue  # module doc: no commanded rates, no test
            dd = np.stack([log.column(c) for c in _GIMBAL_RATES], axis=1).astype(float)
            for start, stop in segments:  # zero-order hold: dd_j acts over [t_j, t_j+1)
                steps = dd[start : stop - 1] * np.diff(t[start:stop])[:, None]
                x[start + 1 : stop] -= np.cumsum(steps, axis=0)
        use = _changing(x, segments)
        if not use.any():
            continue
        x = x[:, use]
        mag = np.maximum(np.max(np.abs(x), axis=0), 1.0)
        cols = tuple(c for c, u in zip(cols, use, strict=True) if u)
        groups.append(
            _Group(name, cols, x, False, np.maximum(floor, _RELATIVE_FLOOR * mag), sided=True)
        )
    return groups


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
    t = log.data["t"].to_numpy(dtype=float)
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
    """Channels far noisier than the testbed says its sensors are (module doc)."""
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
