"""A log as a real testbed writes it, with an answer key: for a lab to rehearse its analysis.

:func:`rehearsal_log` simulates free motion (a free oscillation or a spin-down) on a
jittering clock, with recording gaps, glitches and finite-difference edges, and returns
the log together with what was injected (segments, outlier rows, glitch kinds) in the
words of ``airbearing log check`` and FORMATS.md, so a lab can check that the tools
find exactly those rows before it trusts them on its own logs.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.simulation.artefacts import (
    GLITCH_KINDS,
    sample_times,
    segment_starts,
    with_first_sample_artefact,
    with_gap,
    with_glitches,
    with_jitter,
)
from airbearing.analysis.simulation.on_times import simulate_on_times
from airbearing.analysis.simulation.scenarios import tilt_note
from airbearing.errors import InputError
from airbearing.io.log import Log
from airbearing.io.testbed import Testbed

__all__ = ["Rehearsal", "rehearsal_log", "rehearsal_summary", "parse_glitch", "parse_gap"]


@dataclass(frozen=True)
class Rehearsal:
    """A simulated log with its answer key.

    Attributes
    ----------
    log : Log
        The log (FORMATS.md columns plus ``true_*``).
    segment_rows : tuple of (int, int)
        ``(start, stop)`` rows of each segment (stop exclusive), FORMATS.md gap rule.
    glitches : tuple of (str, tuple of int)
        Each injected glitch kind and the rows it hit.
    first_sample_rows : tuple of int
        Rows where the rate was set to 0 (a finite-difference export's segment starts).
    jitter : float
        The jitter fraction the clock was given.

    Examples
    --------
    >>> import airbearing as ab
    >>> rehearsal = ab.rehearsal_log(ab.load_testbed("seed004-platform"), duration=4.0,
    ...                              initial_rate=(0.0, 0.0, 0.5), gaps=[(1.5, 0.5)],
    ...                              glitches=[("rate_spike", (30,), "wz")], seed=2)
    >>> print(rehearsal)
    70 rows, 2 segment(s) (rows 0-29, 30-69), outlier rows 30, jitter 0
    >>> rehearsal.to_json()["glitches"]
    [{'kind': 'rate_spike', 'rows': [30]}]
    """

    log: Log = field(repr=False)
    segment_rows: tuple
    glitches: tuple
    first_sample_rows: tuple
    jitter: float

    def __str__(self) -> str:
        segs = ", ".join(f"{a}-{b - 1}" for a, b in self.segment_rows)
        rows = ", ".join(map(str, self.outlier_rows)) or "none"
        return (
            f"{self.log.n} rows, {len(self.segment_rows)} segment(s) (rows {segs}), "
            f"outlier rows {rows}, jitter {self.jitter:g}"
        )

    @property
    def outlier_rows(self) -> tuple[int, ...]:
        """Every row an outlier rule should report: glitches and first-sample artefacts."""
        rows = {r for _, hit in self.glitches for r in hit} | set(self.first_sample_rows)
        return tuple(sorted(rows))

    def to_json(self) -> dict:
        """The answer key as JSON.

        Returns
        -------
        dict
            ``segments`` (count), ``segment_rows``, ``outlier_rows``, ``glitches``
            (``{kind, rows}``), ``first_sample_rows``, ``jitter``.
        """
        return {
            "segments": len(self.segment_rows),
            "segment_rows": [list(s) for s in self.segment_rows],
            "outlier_rows": list(self.outlier_rows),
            "glitches": [{"kind": k, "rows": list(rows)} for k, rows in self.glitches],
            "first_sample_rows": list(self.first_sample_rows),
            "jitter": self.jitter,
        }


def parse_glitch(text: str) -> tuple:
    """``"KIND:ROW[,ROW...][@COLUMN]"`` (0-based rows) -> ``(kind, rows[, column])``.

    ``@COLUMN`` names the rate column of a ``rate_spike`` (e.g. ``rate_spike:594@wy``).
    """
    kind, sep, rest = str(text).partition(":")
    if not sep or kind not in GLITCH_KINDS:
        raise InputError(
            f"glitch {text!r}: expected KIND:ROW[,ROW...] with KIND one of "
            f"{', '.join(GLITCH_KINDS)} and 0-based rows"
        )
    rows, at, column = rest.partition("@")
    try:
        out = tuple(int(r) for r in rows.split(","))
    except ValueError:
        raise InputError(f"glitch {text!r}: rows must be 0-based integers") from None
    if at and kind != "rate_spike":
        raise InputError(f"glitch {text!r}: only rate_spike takes @COLUMN (wx, wy or wz)")
    return (kind, out, column) if at else (kind, out)


def parse_gap(text: str) -> tuple[float, float]:
    """``"START:LENGTH"`` (s) -> ``(t_start, length)``; InputError otherwise."""
    start, sep, length = str(text).partition(":")
    try:
        if not sep:
            raise ValueError
        out = (float(start), float(length))
    except ValueError:
        raise InputError(f"gap {text!r}: expected START:LENGTH in s, e.g. 150:20") from None
    if not all(np.isfinite(out)) or out[1] <= 0:
        raise InputError(f"gap {text!r}: expected a finite start and a positive length in s")
    return out


def rehearsal_log(
    testbed: Testbed,
    *,
    duration: float | None = None,
    times=None,
    initial_rate=(0.0, 0.0, 0.0),
    q0=None,
    inputs: Mapping | None = None,
    effects: Mapping | None = None,
    seed: int = 0,
    noise: bool = True,
    attitude_noise: float | None = None,
    jitter: float = 0.0,
    gaps: Sequence = (),
    glitches: Sequence = (),
    first_sample: bool = False,
) -> Rehearsal:
    """Free motion on a real clock with real artefacts, and the rows they hit.

    Parameters
    ----------
    testbed : Testbed
    duration : float, optional
        s; ``round(duration * rate)`` samples at the sensor rate before gaps are cut.
    times : array_like, optional
        Sample times, s, instead of ``duration`` (e.g. the ``t`` column of a lab's own
        log, so the rehearsal has its clock, gaps and segments); jitter and gaps apply on top.
    initial_rate, q0, inputs, effects, noise, attitude_noise
        As :func:`~airbearing.analysis.simulation.on_times.simulate_on_times` (rad/s, SI).
    seed : int
        Seed of the noise; the jitter uses ``seed + 1``.
    jitter : float
        Largest relative change of a sample interval (:func:`with_jitter`), ``< 1``.
    gaps : sequence of (t_start, length)
        Recording gaps, s (:func:`with_gap`), cut in order.
    glitches : sequence of (kind, rows) or (kind, rows, column)
        Glitches (:data:`GLITCH_KINDS`) at 0-based rows of the final log; ``column`` is
        the rate column of a ``rate_spike``.
    first_sample : bool
        Rate 0 at each segment's first row (needs rate columns).

    Returns
    -------
    Rehearsal
        The log and its answer key (segments, glitch rows).

    Raises
    ------
    InputError
        Both or neither of ``duration`` and ``times``, a gap that is not ``(t_start,
        length)`` in s, an unknown glitch kind or a row outside the log.

    Examples
    --------
    A 4 s free spin of seed 004's platform with a 0.5 s recording gap, checked as a lab's
    log would be:

    >>> import airbearing as ab
    >>> rehearsal = ab.rehearsal_log(ab.load_testbed("seed004-platform"), duration=4.0,
    ...                              initial_rate=(0.0, 0.0, 0.5), gaps=[(1.5, 0.5)])
    >>> rehearsal.segment_rows, ab.check_log(rehearsal.log).quality.segments
    (((0, 30), (30, 70)), ((0, 30), (30, 70)))
    """
    if (times is None) == (duration is None):
        raise InputError("give either a duration (s) or the sample times, not both or neither")
    t = sample_times(testbed, duration) if times is None else np.asarray(times, dtype=float)
    if jitter:
        t = with_jitter(t, jitter, seed=seed + 1)
    for gap in gaps:
        if len(gap) != 2:
            raise InputError(f"gap {gap}: expected (t_start, length) in s")
        t, _ = with_gap(t, float(gap[0]), float(gap[1]))
    log = simulate_on_times(
        testbed, t, initial_rate=initial_rate, q0=q0, inputs=inputs, effects=effects,
        seed=seed, noise=noise, attitude_noise=attitude_noise,
    )  # fmt: skip
    first: tuple[int, ...] = ()
    if first_sample:
        log, first = with_first_sample_artefact(log)
    hits = []
    for glitch in glitches:
        kind, rows, *column = glitch
        log, hit = with_glitches(log, rows, kind, column=column[0] if column else None)
        hits.append((kind, hit))
    starts = segment_starts(log)
    segs = tuple(zip(starts, (*starts[1:], log.n), strict=True))
    return Rehearsal(log, segs, tuple(hits), first, float(jitter))


def rehearsal_summary(r: Rehearsal) -> dict:
    """The run in numbers (peak and final true rate, tilt on dof 3, ...) and the answer key."""
    log = r.log
    names = [c for c in ("true_wx", "true_wy", "true_wz") if log.has(c)]
    w = np.linalg.norm(log.columns(names), axis=1)
    out = {
        "peak_rate_deg_s": float(np.rad2deg(w.max())),
        "final_rate_deg_s": float(np.rad2deg(w[-1])),
        # as free_summary: the run's length, the last sample's interval included
        "duration_s": float(log.t[-1] - log.t[0] + log.testbed.sensors.dt),
        "samples": int(log.n),
    }
    q_names = ["true_qw", "true_qx", "true_qy", "true_qz"]
    if log.has(*q_names):  # the same keys as scenarios.free_summary
        out["max_tilt_deg"] = float(np.rad2deg(quat.tilt_of(log.columns(q_names)).max()))
        out.update(tilt_note(out["max_tilt_deg"]))
    return {**out, **r.to_json()}
