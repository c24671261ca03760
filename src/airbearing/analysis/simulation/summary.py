"""What a free run did: its peak and final rate, its largest tilt and whether a spherical
air bearing would have allowed it (the summary ``airbearing simulate`` prints).

The simulated bearing has no tilt stop; :data:`MAX_TILT` is the stop of a tabletop
spherical air bearing (seed 001 Sec. 2).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from airbearing import quaternion as quat

if TYPE_CHECKING:
    from airbearing.analysis.simulation.simulate import SimResult

__all__ = ["MAX_TILT", "free_summary", "tilt_note"]

#: rad, the tilt a spherical air bearing allows (seed 001 Sec. 2 cites +-45 and +-50 deg).
MAX_TILT = math.radians(45.0)


def free_summary(result: SimResult) -> dict:
    """Peak and final rate, largest tilt and the run length of a free oscillation.

    Parameters
    ----------
    result : SimResult

    Returns
    -------
    dict
        ``peak_rate_deg_s``, ``final_rate_deg_s`` (deg/s), ``duration_s`` (s), ``samples``
        and, on dof 3, ``max_tilt_deg`` (deg, body z from lab z) with ``tilt_note`` when it
        passes what a spherical air bearing allows (:func:`tilt_note`).

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.free_oscillation(ab.load_testbed("seed004-platform"),
    ...                           initial_rate=(0.0, 0.0, 0.5), duration=5.0)  # rad/s, s
    >>> summary = ab.free_summary(run)
    >>> summary["samples"], summary["duration_s"], round(summary["max_tilt_deg"])  # -, s, deg
    (100, 5.0, 34)
    """
    m = result.model
    w = result.x[:, m.index(["wx", "wy", "wz"] if m.dof == 3 else ["wz"])]
    out = {
        "peak_rate_deg_s": float(np.rad2deg(np.linalg.norm(w, axis=1).max())),
        "final_rate_deg_s": float(np.rad2deg(np.linalg.norm(w[-1]))),
        "duration_s": float(result.t[-1] + m.testbed.sensors.dt),
        "samples": int(len(result.t)),
    }
    if m.dof == 3:
        out["max_tilt_deg"] = float(np.rad2deg(quat.tilt_of(result.x[:, 0:4]).max()))
        out.update(tilt_note(out["max_tilt_deg"]))
    return out


def tilt_note(max_tilt_deg: float) -> dict:
    """``{"tilt_note": words}`` when a dof-3 run tilts past what a spherical bearing allows.

    The simulated bearing has no tilt stop, so a free run can swing past the +-45 deg of a
    tabletop spherical air bearing (seed 001 Sec. 2 cites +-45 and +-50 deg;
    :data:`MAX_TILT`), where a testbed would hit its
    stop. Empty within it.

    Parameters
    ----------
    max_tilt_deg : float
        deg, the run's largest angle between body z and lab z.

    Returns
    -------
    dict
    """
    limit = float(np.rad2deg(MAX_TILT))
    if not max_tilt_deg > limit:
        return {}
    return {
        "tilt_note": (
            f"the platform tilted {max_tilt_deg:.1f} deg; a spherical air bearing stops at "
            f"about +-{limit:.0f} deg (seed 001 Sec. 2: +-45 to +-50 deg) and the simulated "
            "bearing has none, so past that this run is not what a testbed would do"
        )
    }
