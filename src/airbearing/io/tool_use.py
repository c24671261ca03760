"""What each tool can use of a log (``airbearing log check``'s "tools" table).

From the log's segments and outlier rows (:mod:`airbearing.io.quality`) and its
testbed: replays need a segment of 2 samples, fits a segment of
:data:`MIN_FIT_SAMPLES` usable samples and some motion (:mod:`airbearing.io.motion`),
balancing the slider columns.
"""

from __future__ import annotations

import numpy as np

from airbearing.io.log import Log
from airbearing.io.quality import LogQuality

__all__ = ["MIN_FIT_SAMPLES", "TOOLS", "tool_use"]


#: Usable samples a segment needs for identification and discrepancy windows: a
#: free oscillation must show some motion; 20 samples are 1 s at 20 Hz.
MIN_FIT_SAMPLES = 20
#: The tools ``log check`` reports on, in the order it prints them.
TOOLS: tuple[str, ...] = ("simulate replay", "identify", "discrepancy", "replay", "balance")


def tool_use(log: Log, quality: LogQuality) -> dict[str, tuple[bool, str]]:
    """Which tools can use this log, and why (or why not).

    Parameters
    ----------
    log : Log
        Validated with its testbed (so the testbed's required columns are present).
    quality : LogQuality

    Returns
    -------
    dict of str to (bool, str)
        For each of :data:`TOOLS`: whether it can use the log and one sentence why.
        Replays need a segment of 2 samples; fits need a segment of at least
        :data:`MIN_FIT_SAMPLES` usable samples; balancing needs sliders.
    """
    tb = log.testbed
    usable = quality.usable_mask()
    longest = max((int(np.sum(usable[a:b])) for a, b in quality.segments), default=0)
    n_fit = sum(1 for a, b in quality.segments if np.sum(usable[a:b]) >= MIN_FIT_SAMPLES)
    segs = f"{quality.n_segments} segment(s), {len(quality.outlier_rows)} outlier row(s) left out"
    measured = "attitude only (sensors.gyro = false)" if tb and not tb.sensors.gyro else "rates"
    out: dict[str, tuple[bool, str]] = {}
    replay_ok = longest >= 2
    why_replay = (
        f"{segs}; each segment starts afresh from its logged state"
        if replay_ok
        else "no segment has 2 usable samples"
    )
    out["simulate replay"] = (replay_ok, why_replay)
    if n_fit:
        why_fit = (  # each count said once
            f"{n_fit} of {quality.n_segments} segment(s) with >= {MIN_FIT_SAMPLES} usable "
            f"samples, {len(quality.outlier_rows)} outlier row(s) left out; fits {measured}"
        )
        out["identify"] = (True, why_fit)
        out["discrepancy"] = (True, why_fit)
    else:
        why = f"no segment has {MIN_FIT_SAMPLES} usable samples (longest: {longest})"
        out["identify"] = (False, why)
        out["discrepancy"] = (False, why)
        if tb is not None and tb.kind == "cmg" and tb.body.dof == 1:
            out["identify"] = _cmg_identify_minimum(quality, usable)
    out["replay"] = (replay_ok, why_replay)
    if quality.no_motion:  # nothing to fit: the model is not excited
        for tool in ("identify", "discrepancy"):
            out[tool] = (False, quality.no_motion)
    if quality.gyro_disagreement:  # a fit on it would be confidently wrong
        why = quality.gyro_disagreement[0]
        for tool in ("simulate replay", "identify", "discrepancy", "replay"):
            out[tool] = (False, why)
    if tb is None:
        out["balance"] = (False, "no testbed given")
    elif tb.kind != "platform":
        out["balance"] = (False, "kind = 'cmg': no sliding masses to balance with")
    elif tb.masses is None:
        out["balance"] = (False, "passive platform (no [masses]): nothing to balance with")
    elif not log.has("s1", "s2", "s3"):
        out["balance"] = (False, "no slider columns s1, s2, s3")
    else:
        out["balance"] = (replay_ok, "sliders and attitude logged: balancing runs can be checked")
    return out


def _cmg_identify_minimum(quality: LogQuality, usable: np.ndarray) -> tuple[bool, str]:
    """``identify``'s own minimum for a dof-1 CMG log (its momentum regression,
    analysis/identification/cmg_inertia.py): the usable rows of each segment with at least
    3 of them, more rows than unknowns (1/J_z and one constant per segment, without
    friction)."""
    counts = [int(np.sum(usable[a:b])) for a, b in quality.segments]
    pieces = [c for c in counts if c >= 3]
    rows, unknowns = sum(pieces), 1 + len(pieces)
    if rows > unknowns:
        return True, (
            f"{rows} usable sample(s) in {len(pieces)} segment(s), more than the momentum "
            f"regression's {unknowns} unknowns; no segment has {MIN_FIT_SAMPLES} usable "
            "samples: a weak fit"
        )
    return False, f"{rows} usable sample(s) for {unknowns} unknowns (1/J_z, one per segment)"
