"""Four-CMG pyramid: cluster momentum and its Jacobian.

Two forms are kept explicit and named:

* **physical**: ``h(delta) = h0 * H(delta)`` in N m s, Jacobian ``h0 * A(delta)``;
* **normalised**: ``H(delta)`` and ``A(delta)`` without ``h0`` (dimensionless), the
  form seed 001 uses inside its steering law (eq. 16) and whose theoretical
  slews the package reproduces.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = [
    "momentum_normalised",
    "momentum",
    "jacobian_normalised",
    "jacobian_eq15",
    "cmg_functions",
]


def momentum_normalised(delta, beta):
    """Normalised cluster momentum ``H(delta)`` (seed 001 eq. 12 without h0).

    Parameters
    ----------
    delta : casadi SX/MX (4,)
        Gimbal angles, rad.
    beta : float or casadi scalar
        Skew angle, rad.
    """
    cb, sb = ca.cos(beta), ca.sin(beta)
    c = [ca.cos(delta[i]) for i in range(4)]
    s = [ca.sin(delta[i]) for i in range(4)]
    # seed 001 eq. 12
    return ca.vertcat(
        -cb * s[0] - c[1] + cb * s[2] + c[3],
        c[0] - cb * s[1] - c[2] + cb * s[3],
        sb * (s[0] + s[1] + s[2] + s[3]),
    )


def momentum(delta, beta, h0):
    """Cluster momentum ``h = h0 H(delta)`` in N m s (seed 001 eqs. 12-13)."""
    return h0 * momentum_normalised(delta, beta)


def jacobian_normalised(delta, beta):
    """``A(delta) = dH/d delta`` (3x4) by CasADi automatic differentiation (seed 001 eq. 14)."""
    return ca.jacobian(momentum_normalised(delta, beta), delta)


def jacobian_eq15(delta, beta):
    """The closed form of seed 001 eq. 15, for checking the CasADi Jacobian (NumPy)."""
    d = np.asarray(delta, dtype=float)
    cb, sb = np.cos(beta), np.sin(beta)
    c, s = np.cos(d), np.sin(d)
    # seed 001 eq. 15
    return np.array(
        [
            [-cb * c[0], s[1], cb * c[2], -s[3]],
            [-s[0], -cb * c[1], s[2], cb * c[3]],
            [sb * c[0], sb * c[1], sb * c[2], sb * c[3]],
        ]
    )


def cmg_functions() -> dict[str, ca.Function]:
    """Compiled CasADi Functions ``H(delta, beta)`` and ``A(delta, beta)`` (normalised)."""
    delta = ca.SX.sym("delta", 4)
    beta = ca.SX.sym("beta")
    H = momentum_normalised(delta, beta)
    A = jacobian_normalised(delta, beta)
    return {
        "H": ca.Function("H", [delta, beta], [H], ["delta", "beta"], ["H"]),
        "A": ca.Function("A", [delta, beta], [A], ["delta", "beta"], ["A"]),
    }
