"""The closed-loop poles of a reaction-wheel loop without those of the wheels' stored
momentum: a constant wheel speed is an equilibrium at any value, so each momentum direction
the loop does not regulate is a pole at z = 1 (s = 0) whose mode moves the wheel speeds and
nothing else (neutral, not unstable)."""

from __future__ import annotations

import numpy as np

from airbearing.design.attitude import PID_STATES

__all__ = ["body_state_mask", "without_momentum_poles"]


#: |z - 1| (or |s| times the sample time) within which a pole is the wheels' momentum,
#: and the largest share of its mode on the body and PID states.
_MOMENTUM_TOL = 1e-8
_MOMENTUM_SHARE = 1e-6


def body_state_mask(labels) -> np.ndarray:
    """True for the states of an interconnected wheel loop that a stored-momentum mode
    leaves at rest: the body's (not ``W<i>``) and the PID's (controller states ``c0..c9``,
    :data:`~airbearing.design.attitude.PID_STATES`); the delay's and the speed targets'
    states may move with the wheels."""
    out = []
    for lbl in labels:
        name = lbl.split("_", 1)[1] if "_" in lbl else lbl
        if lbl.startswith("plant_"):
            out.append(not (name.startswith("W") and name[1:].isdigit()))
        elif lbl.startswith("controller_c") and name[1:].isdigit():
            out.append(int(name[1:]) < PID_STATES)
        else:
            out.append(False)
    return np.array(out, dtype=bool)


def without_momentum_poles(A, body_mask, discrete: bool = True, dt: float = 1.0) -> np.ndarray:
    """The eigenvalues of the closed-loop ``A`` without those of stored wheel momentum:
    at z = 1 (s = 0) within :data:`_MOMENTUM_TOL`, with a mode that leaves the states of
    ``body_mask`` at rest (share below :data:`_MOMENTUM_SHARE`)."""
    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return np.zeros(0, complex)
    lam, V = np.linalg.eig(A)
    at = np.abs(lam - 1) if discrete else np.abs(lam) * dt
    keep = np.ones(lam.size, dtype=bool)
    for i in np.nonzero(at < _MOMENTUM_TOL)[0]:
        v = np.abs(V[:, i])
        if v[body_mask].max(initial=0.0) <= _MOMENTUM_SHARE * v.max():
            keep[i] = False
    return lam[keep]
