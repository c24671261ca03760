"""CMG steering laws and gimbal-rate limiting, as CasADi Functions for the compiled loop.

A steering law maps the wanted cluster momentum rate to gimbal rates:
``steer(A, h_dot, delta, t) -> delta_dot`` with ``A`` the 3x4 Jacobian (normalised or
physical, the caller decides; see :mod:`airbearing.models.cmg`), ``h_dot`` the wanted
momentum rate (3,), ``delta`` the gimbal angles (4,) and ``t`` the time (s).
"""

from __future__ import annotations

import casadi as ca

from airbearing.errors import InputError

__all__ = ["STEERING_LAWS", "steering_function", "saturate_rates", "moore_penrose"]


def moore_penrose(A, h_dot):
    """Moore-Penrose pseudo-inverse steering ``A^T (A A^T)^-1 h_dot`` (seed 001 eq. 16)."""
    return ca.mtimes(A.T, ca.solve(ca.mtimes(A, A.T), h_dot))


def _mp(**options) -> ca.Function:
    if options:
        raise InputError(f"steering 'mp' takes no options, got {sorted(options)}")
    A, h_dot, delta, t = (
        ca.SX.sym("A", 3, 4),
        ca.SX.sym("h_dot", 3),
        ca.SX.sym("delta", 4),
        ca.SX.sym("t"),
    )
    return ca.Function(
        "steer_mp", [A, h_dot, delta, t], [moore_penrose(A, h_dot)],
        ["A", "h_dot", "delta", "t"], ["delta_dot"],
    )


#: Steering-law factories by CLI name; each returns a CasADi Function.
STEERING_LAWS = {"mp": _mp}


def steering_function(name: str, **options) -> ca.Function:
    """The steering law ``name`` (see :data:`STEERING_LAWS`) as a CasADi Function."""
    try:
        factory = STEERING_LAWS[name]
    except KeyError:
        raise InputError(
            f"unknown steering law '{name}': expected one of {', '.join(STEERING_LAWS)}"
        ) from None
    return factory(**options)


def saturate_rates(dd, limit: float, mode: str = "scale"):
    """Limit gimbal rates to ``limit`` (rad/s).

    ``mode="scale"`` scales all four together when the largest exceeds the limit,
    keeping the direction of the motion (seed 001 eq. 4); ``mode="clip"`` clips each
    gimbal on its own (changes the direction, and so the torque).
    """
    if limit == float("inf"):
        return dd
    if mode == "scale":
        peak = ca.mmax(ca.fabs(dd))
        return ca.if_else(peak > limit, dd * (limit / peak), dd)  # seed 001 eq. 4
    if mode == "clip":
        return ca.fmin(ca.fmax(dd, -limit), limit)
    raise InputError(f"rate limiting mode '{mode}': expected 'scale' or 'clip'")
