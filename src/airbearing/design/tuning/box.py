"""The uncertainty box: the plant parameters at its corners."""

from __future__ import annotations

import numpy as np

from airbearing.design.linearise import scaled_params
from airbearing.design.loops import Loop
from airbearing.design.tuning.spec import Spec

__all__ = ["corners", "offset_range"]


def corners(loop: Loop, spec: Spec) -> list[tuple[str, np.ndarray]]:
    """The uncertainty corners: inertia x (1 -+ u) and, dof 3, the vertical offset range
    (:func:`offset_range`)."""
    return [(label, p) for label, p, _ in _corner_grid(loop, spec)]


#: The testbed's vertical offset is known to +-50 % before seed 004's step two identifies it.
_OFFSET_SPREAD = 0.5
#: What step two leaves, relative to the testbed's vertical offset, in the worst case (seed
#: 004: "the estimation error limit was found to be of 2% in the worst case"); the same
#: number as :data:`airbearing.analysis.balancing.runs.STEP2_ERROR`, the offset
#: ``airbearing balance`` simulates by default (a test checks they agree).
_STEP2_ERROR = 0.02


def offset_range(loop: Loop, spec: Spec) -> tuple[float, float] | None:
    """The vertical CM offset range ``(lo, hi)`` of the box, m; None off a dof-3 platform.

    ``spec.offset_range`` when given. By default, every offset at which the in-plane
    balancing runs: from before seed 004's step two, the testbed's own offset ``r_z`` and
    50 % beyond it (not yet identified), to after it, ``0.02 r_z`` (what step two leaves
    in the worst case, the platform ``airbearing balance`` and seed 000's experiments
    run on). For seed 004's platform, -3.9 mm to -0.052 mm. The attitude loop of a
    reaction-wheel rig keeps the testbed's offset unless ``spec.offset_range`` is given.
    """
    m = loop.model
    if not (m.dof == 3 and m.kind == "platform"):
        return None
    if loop.wheels and spec.offset_range is None:  # no balancing run: the testbed's offset
        return None
    if spec.offset_range is not None:
        return tuple(spec.offset_range)
    rz0 = float(loop.p[m.index("r_z", "p")[0]])
    ends = (rz0 * (1 + _OFFSET_SPREAD), rz0 * _STEP2_ERROR)
    return min(ends), max(ends)


def _corner_grid(loop: Loop, spec: Spec) -> list[tuple[str, np.ndarray, bool]]:
    """:func:`corners` with, for each, whether it is a vertex of the box (every
    uncertain parameter at an end of its range). The offsets are the ends of the range
    and the testbed's own offset when inside it (else the middle of the range)."""
    m = loop.model
    u = spec.inertia_uncertainty
    scales = sorted({1.0 - u, 1.0, 1.0 + u})
    box = offset_range(loop, spec)
    if box is not None:
        lo, hi = box
        rz0 = float(loop.p[m.index("r_z", "p")[0]])
        offsets = sorted({lo, rz0 if lo <= rz0 <= hi else 0.5 * (lo + hi), hi})
    else:
        offsets = [None]
    out = []
    for s in scales:
        for r in offsets:
            label = f"J x {s:g}" + ("" if r is None else f", r_z = {r * 1e3:.3g} mm")
            vertex = s in (scales[0], scales[-1]) and r in (offsets[0], offsets[-1])
            out.append((label, scaled_params(m, loop.p, inertia_scale=s, r_z=r), vertex))
    return out
