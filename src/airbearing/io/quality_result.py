"""The result of a log's quality check: :class:`LogQuality` and its :class:`Outlier` rows.

Made by :func:`airbearing.io.quality.assess` (the rule is in :mod:`airbearing.io.quality`'s
docstring); every tool reads a log's segments, outlier rows and usable mask from it
(``Log.quality``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from airbearing.io.discontinuity import RowFinding

__all__ = ["INPUT_COLUMNS", "LogQuality", "Outlier"]

#: Log columns that models take as inputs: a glitch in one breaks the segment there
#: (:meth:`LogQuality.input_segments`).
INPUT_COLUMNS = frozenset(
    ("d1", "d2", "d3", "d4", "dd1", "dd2", "dd3", "dd4", "s1", "s2", "s3", "mx", "my", "mz")
    + ("bx", "by", "bz")
)


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
        as ``d - D``, :mod:`airbearing.io.quality`).
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
