"""The uncertainty box: the plant parameters at its corners."""

from __future__ import annotations

import numpy as np

from airbearing.design.linearise import scaled_params
from airbearing.design.loops import Loop
from airbearing.design.tuning.spec import Spec

__all__ = ["corners"]


def corners(loop: Loop, spec: Spec) -> list[tuple[str, np.ndarray]]:
    """The uncertainty corners: inertia x (1 -+ u) and, dof 3, the vertical offset range."""
    return [(label, p) for label, p, _ in _corner_grid(loop, spec)]


def _corner_grid(loop: Loop, spec: Spec) -> list[tuple[str, np.ndarray, bool]]:
    """:func:`corners` with, for each, whether it is a vertex of the box (every
    uncertain parameter at an end of its range)."""
    m = loop.model
    u = spec.inertia_uncertainty
    scales = sorted({1.0 - u, 1.0, 1.0 + u})
    if m.dof == 3 and m.kind == "platform":
        rz0 = loop.p[m.index("r_z", "p")[0]]
        lo, hi = (
            spec.offset_range
            if spec.offset_range is not None
            else (rz0 - 0.5 * abs(rz0), rz0 + 0.5 * abs(rz0))
        )
        offsets = sorted({lo, rz0, hi})
    else:
        offsets = [None]
    out = []
    for s in scales:
        for r in offsets:
            label = f"J x {s:g}" + ("" if r is None else f", r_z = {r * 1e3:.3g} mm")
            vertex = s in (scales[0], scales[-1]) and r in (offsets[0], offsets[-1])
            out.append((label, scaled_params(m, loop.p, inertia_scale=s, r_z=r), vertex))
    return out
