"""What a CMG slew ran into: the cluster's momentum envelope and a chattering rate command.

Saturation. The cluster of four gimbals stores at most ``h0 S(u)`` along a unit direction
``u`` (body axes), ``S(u) = sum_i sqrt(1 - (g_i . u)^2)`` with ``g_i`` the gimbal axes:
each wheel's momentum turns in the plane normal to its gimbal axis, so its largest
component along ``u`` is ``h0 |g_i x u|`` (the momentum envelope, seed 001 eq. 12 with
every momentum as far along ``u`` as its gimbal plane allows; ``4 h0 sin(beta)`` along
the pyramid's axis). A slew about ``u`` needs the body's momentum from the cluster; when
the cluster's momentum along ``u`` is at the envelope and the loop's wanted momentum rate
(seed 001 eq. 11, ``h_dot = -T_c - w x h``, along ``u``: ``-T_c . u``) still points
outward, the slew asks for more
than the cluster can store: the body turns at the rate the stored momentum gives, not at
the one the loop asks for.

Chatter. At the envelope the Jacobian (seed 001 eq. 15) has no column along ``u`` (a
singular gimbal set), and a steering law that keeps asking for momentum along ``u``
drives the gimbals back and forth across it: the gimbal-rate command reverses sign from
one sample to the next (a limit cycle at the loop's Nyquist frequency). A normal
rest-to-rest slew reverses each gimbal's command once or twice over seconds.
"""

from __future__ import annotations

import numpy as np

from airbearing.analysis.cmg.singularity import pyramid_geometry

__all__ = [
    "ENVELOPE_FRACTION",
    "CHATTER_RATE_FRACTION",
    "CHATTER_GAP_SAMPLES",
    "CHATTER_MIN_REVERSALS",
    "SINGULAR_MEASURE",
    "envelope_capacity",
    "saturation_episodes",
    "chatter_episodes",
    "slew_warnings",
]

#: Fraction of the envelope along the slew axis from which the cluster counts as at its
#: envelope: 1 % short of it, every gimbal within about 8 deg of the envelope's gimbal set
#: (cos 8.1 deg = 0.99). Seed 001's own 180 deg slew (Table 7) peaks at 89 %.
ENVELOPE_FRACTION = 0.99
#: A sign reversal of a gimbal's rate command counts toward chatter only when the command
#: is at least this fraction of the gimbal-rate limit on both sides (sensor noise around a
#: zero command is not chatter).
CHATTER_RATE_FRACTION = 0.05
#: Reversals at most this many samples apart belong to one episode (as do saturated
#: samples): a command reversing every sample or every other sample.
CHATTER_GAP_SAMPLES = 2
#: An episode with fewer reversals than this is a change of direction, not chatter (two
#: back-and-forth cycles).
CHATTER_MIN_REVERSALS = 4
#: Singularity measure ``sqrt(det(A A^T))`` below which a chatter episode's gimbals count
#: as at a singular set (:func:`airbearing.analysis.cmg.singularity.singularity_summary`'s
#: threshold; 1.09 with every gimbal at 0 on seed 001's 54.73 deg pyramid).
SINGULAR_MEASURE = 0.2


def envelope_capacity(beta: float, u) -> float:
    """The most momentum the pyramid stores along ``u``, in units of ``h0``.

    Parameters
    ----------
    beta : float
        Skew angle, rad.
    u : sequence of 3 float
        Direction, body axes (normalised here).

    Returns
    -------
    float
        ``S(u) = sum_i sqrt(1 - (g_i . u)^2)``, -; ``4 sin(beta)`` along the pyramid's axis.
    """
    u = np.asarray(u, float) / np.linalg.norm(u)
    g = pyramid_geometry(beta).g
    return float(np.sum(np.sqrt(np.clip(1.0 - (g @ u) ** 2, 0.0, None))))


def _time(t) -> float:
    """A sample time, s, without the round-off of ``k dt`` (``9.600000000000001``)."""
    return round(float(t), 9)


def _runs(mask: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """``[first, last]`` sample indices of the runs of ``mask``, runs at most ``gap``
    samples apart merged."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > gap)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def saturation_episodes(t, H, torque, u, capacity: float) -> tuple[float, list[dict]]:
    """When the cluster's momentum along ``u`` was at its envelope and the loop asked for more.

    Parameters
    ----------
    t : (N,) array
        s, sample times.
    H : (N, 3) array
        Cluster momentum per ``h0`` at each sample (seed 001 eq. 12), body axes.
    torque : (N, 3) array
        The loop's torque command ``T_c`` (seed 001 eq. 19; per ``h0`` or in N m, only its
        sign along ``u`` counts). The wanted momentum rate along ``u`` is ``-T_c . u``
        (eq. 11: ``(w x h) . u`` vanishes for a rotation about ``u``), outward when it has
        the sign of ``H . u``.
    u : (3,) array
        Unit slew axis, body axes.
    capacity : float
        :func:`envelope_capacity` along ``u``, -.

    Returns
    -------
    (float, list of dict)
        The peak of ``|u . H| / capacity`` (-) and the episodes, each ``{"start_s",
        "end_s"}`` (s, first and last saturated sample).
    """
    frac = (np.asarray(H) @ u) / capacity
    outward = -(np.asarray(torque) @ u) * frac > 0
    mask = (np.abs(frac) >= ENVELOPE_FRACTION) & outward
    t = np.asarray(t)
    episodes = [{"start_s": _time(t[a]), "end_s": _time(t[b])} for a, b in
                _runs(mask, CHATTER_GAP_SAMPLES)]  # fmt: skip
    return float(np.max(np.abs(frac))) if frac.size else 0.0, episodes


def chatter_episodes(t, dd, limit: float) -> list[dict]:
    """When the gimbal-rate command reversed sign from sample to sample.

    Parameters
    ----------
    t : (N,) array
        s, sample times.
    dd : (N, 4) array
        rad/s, the commanded gimbal rates held over each sample.
    limit : float
        rad/s, the gimbal-rate limit (``cmg.max_gimbal_rate``).

    Returns
    -------
    list of dict
        Each ``{"start_s", "end_s"}`` (s, the first and last sample of a reversal),
        ``samples`` (samples from the first to the last), ``reversal_samples`` (samples at
        which some gimbal's command reversed sign).
    """
    dd = np.asarray(dd, float)
    t = np.asarray(t)
    if len(dd) < 2:
        return []
    a, b = dd[:-1], dd[1:]
    big = np.minimum(np.abs(a), np.abs(b)) >= CHATTER_RATE_FRACTION * limit
    rev = np.any((a * b < 0) & big, axis=1)  # reversal between sample k and k + 1
    mask = np.concatenate([[False], rev])  # at sample k + 1
    out = []
    for s, e in _runs(mask, CHATTER_GAP_SAMPLES):
        n = int(mask[s : e + 1].sum())
        if n >= CHATTER_MIN_REVERSALS:
            out.append({"start_s": _time(t[s - 1]), "end_s": _time(t[e]),
                        "samples": int(e - s + 2), "reversal_samples": n})  # fmt: skip
    return out


def _overlaps(a: dict, b: dict) -> bool:
    return a["start_s"] <= b["end_s"] and b["start_s"] <= a["end_s"]


def slew_warnings(saturation, chatter, *, capacity_nms: float, capacity_h0: float,
                  rate_cap_deg_s: float | None, gimbals_deg, measure) -> list[str]:  # fmt: skip
    """The saturation and chatter episodes in words, with their times.

    ``gimbals_deg``: ``(t, delta)`` of the run (s, deg), for the gimbal angles of each
    chatter episode; ``measure``: the singularity measure at those samples (-);
    ``rate_cap_deg_s``: the body rate the envelope allows about the slew axis (deg/s),
    or None.
    """
    out = []
    for ep in saturation:
        cap = "" if rate_cap_deg_s is None else (
            f"; the body turns at most at {rate_cap_deg_s:.3g} deg/s about that axis "
            "(that momentum over the inertia)"
        )  # fmt: skip
        out.append(
            f"cluster momentum saturated from {ep['start_s']:.2f} s to {ep['end_s']:.2f} s: "
            f"at its envelope along the slew axis ({capacity_nms:.3g} N m s, "
            f"{capacity_h0:.3g} h0) while the loop asked for more; the slew needs more "
            f"momentum than the cluster can store along that axis{cap}"
        )
    t, d = gimbals_deg
    for ep in chatter:
        k = (t >= ep["start_s"] - 1e-9) & (t <= ep["end_s"] + 1e-9)
        lo, hi = float(np.min(d[k])), float(np.max(d[k]))
        m_min = float(np.min(np.asarray(measure)[k]))
        where = (
            ", while the cluster was at its momentum envelope"
            if any(_overlaps(ep, s) for s in saturation)
            else ""
        )
        singular = (
            f"; a singular gimbal set (singularity measure sqrt(det(A A^T)) down to "
            f"{m_min:.2g}), where the cluster can give no torque along one direction"
            if m_min < SINGULAR_MEASURE
            else ""
        )
        out.append(
            f"gimbal-rate command chattered from {ep['start_s']:.2f} s to {ep['end_s']:.2f} "
            f"s: it reversed sign at {ep['reversal_samples']} of {ep['samples']} samples, "
            f"gimbals between {lo:.0f} and {hi:.0f} deg{where}{singular}"
        )
    return out
