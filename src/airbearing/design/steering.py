"""CMG steering laws and gimbal-rate limiting, as CasADi Functions for the compiled loop.

A steering law maps the wanted cluster momentum rate to gimbal rates:
``steer(A, h_dot, delta, t) -> delta_dot`` with ``A`` the 3x4 Jacobian (normalised or
physical, the caller decides; see :mod:`airbearing.models.cmg`), ``h_dot`` the wanted
momentum rate (3,), ``delta`` the gimbal angles (4,) and ``t`` the time (s).

Every law here has the form ``A^T (A A^T + lambda E)^-1 h_dot`` and differs in the
damping ``lambda`` and the weighting matrix ``E``:

========  ==========================================================================
``mp``    Moore-Penrose, ``lambda = 0`` (seed 001 eq. 16).
``sr``    singularity-robust inverse, ``E = I`` (Nakamura & Hanafusa 1986; Wie, Bailey
          & Heiberg, JGCD 24(5), 2001), ``lambda = lambda0 exp(-mu m^2)``.
``gsr``   generalised SR inverse with the deterministic dither of Wie (JGCD 28(5),
          2005): ``E = [[1, e3, e2], [e3, 1, e1], [e2, e1, 1]]``,
          ``e_i = epsilon0 sin(omega t + phi_i)``.
``sda``   singular-direction avoidance (Ford & Hall, JGCD 23(4), 2000): the damping
          acts only on the direction of the smallest singular value, so the torque in
          the two well-conditioned directions stays exact; ``E = W(A A^T) + D(t)``
          with ``W = (I + A A^T / s_ref)^-2`` (1 on the singular direction, about 0 on
          the others, defined when singular values coincide) plus the off-diagonal
          dither ``D(t)`` of Wie (2005), so that a demand exactly along the singular
          direction does not leave the cluster stuck (``epsilon0 = 0`` gives plain SDA).
========  ==========================================================================

``m = sqrt(det(A A^T))`` is the singularity measure of the *normalised* Jacobian (each
column of the normalised pyramid Jacobian is a unit vector, so ``trace(A A^T) = 4``;
the laws divide a physical ``h0 A`` by ``sqrt(trace(A A^T) / 4)`` to find ``h0``, which
makes ``lambda0`` dimensionless and the same law serve both forms; ``h0_scale`` may be
given instead).

Every law accepts null motion, ``null_motion_gain > 0`` (and ``skew``, rad): the
gradient of ``m(delta)`` (CasADi, exact) projected on the null space of ``A``,
``gain * n (n . grad m) / |n|^2`` with ``n`` the vector of signed 3x3 minors of ``A``
(``A n = 0`` identically), which steers the gimbals away from singular sets and
produces no torque.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from airbearing.errors import InputError
from airbearing.models.cmg import jacobian_normalised

__all__ = [
    "STEERING_LAWS",
    "STEERING_DEFAULTS",
    "WIE_2005",
    "steering_function",
    "saturate_rates",
    "moore_penrose",
    "sr_inverse",
    "singularity_measure",
    "h0_scale_of",
    "wie_dither",
    "sda_weight",
    "null_vector",
    "null_motion",
    "check_skew",
]

#: Wie (2005) parameters of the SR/GSR schedule and dither: lambda0, mu, epsilon0,
#: omega (rad/s) and the phases phi_1..3 (rad).
WIE_2005 = {
    "lambda0": 0.01,
    "mu": 10.0,
    "epsilon0": 0.01,
    "omega": math.pi / 2,
    "phases": (0.0, math.pi / 2, math.pi),
}

_COMMON = {"null_motion_gain": 0.0, "skew": None, "h0_scale": None}

#: Options of each law with their defaults (unknown options are rejected).
STEERING_DEFAULTS: dict[str, dict] = {
    "mp": dict(_COMMON),
    "sr": {**_COMMON, "lambda0": WIE_2005["lambda0"], "mu": WIE_2005["mu"]},
    "gsr": {**_COMMON, **WIE_2005},
    "sda": {**_COMMON, **WIE_2005, "s_ref": 0.05},
}

_M_FLOOR = 1e-12  # normalised det floor: keeps grad m finite where m = 0 exactly


def check_skew(skew, option: str = "skew") -> float:
    """Validate a pyramid skew angle in rad: ``0 < skew < pi/2``; returns it as float."""
    try:
        b = float(skew)
    except (TypeError, ValueError):
        raise InputError(f"{option} {skew!r}: expected a number in rad") from None
    if not (0.0 < b < math.pi / 2) or not math.isfinite(b):
        deg = math.degrees(b) if math.isfinite(b) else b
        raise InputError(
            f"{option} = {deg:g} deg ({b:g} rad): "
            "expected a pyramid skew angle strictly between 0 and 90 deg"
        )
    return b


def moore_penrose(A, h_dot):
    """Moore-Penrose pseudo-inverse steering ``A^T (A A^T)^-1 h_dot`` (seed 001 eq. 16)."""
    return ca.mtimes(A.T, ca.solve(ca.mtimes(A, A.T), h_dot))


def sr_inverse(A, h_dot, lam, E=None):
    """Damped inverse ``A^T (A A^T + lam E)^-1 h_dot`` (``E = I`` by default).

    With ``lam = 0`` it is the Moore-Penrose inverse (seed 001 eq. 16).

    Parameters
    ----------
    A : casadi SX/MX/DM (3, 4)
        Jacobian (normalised, or physical in N m s per rad).
    h_dot : (3,)
        Wanted momentum rate (units of ``A`` per s).
    lam : scalar
        Damping, units of ``A A^T``.
    E : (3, 3), optional
        Weighting of the damping.
    """
    M = ca.mtimes(A, A.T)
    E = ca.DM.eye(3) if E is None else E
    return ca.mtimes(A.T, ca.solve(M + lam * E, h_dot))


def h0_scale_of(A):
    """``h0`` of a physical pyramid Jacobian ``h0 A_n``: ``sqrt(trace(A A^T) / 4)``.

    Each column of the normalised Jacobian (seed 001 eq. 15) is a unit torque direction,
    so ``trace(A_n A_n^T) = 4``; the normalised form gives 1.
    """
    return ca.sqrt(ca.sumsqr(A) / 4)


def singularity_measure(A):
    """``m = sqrt(det(A A^T))`` (CasADi); 0 exactly on the singular sets."""
    return ca.sqrt(ca.fmax(ca.det(ca.mtimes(A, A.T)), 0))


def wie_dither(t, epsilon0: float, omega: float, phases) -> ca.SX:
    """Off-diagonal dither of Wie (2005): ``[[0, e3, e2], [e3, 0, e1], [e2, e1, 0]]``.

    ``e_i = epsilon0 sin(omega t + phi_i)`` (t in s, omega in rad/s, phases in rad).
    """
    e1, e2, e3 = (epsilon0 * ca.sin(omega * t + p) for p in phases)
    return ca.vertcat(ca.horzcat(0, e3, e2), ca.horzcat(e3, 0, e1), ca.horzcat(e2, e1, 0))


def sda_weight(M, s_ref: float):
    """Singular-direction weight ``(I + M / s_ref)^-2`` of ``M = A A^T`` (normalised).

    Its eigenvalues are ``(1 + sigma_i^2 / s_ref)^-2``: 1 on the singular direction
    (``sigma_3 -> 0``) and small on the well-conditioned ones, as the projector
    ``u_3 u_3^T`` of Ford & Hall's SDA, but smooth where singular values coincide.
    """
    Winv = ca.DM.eye(3) + M / s_ref
    W = ca.inv(Winv)
    return ca.mtimes(W, W)


def null_vector(A):
    """Signed 3x3 minors ``n`` of the 3x4 ``A``: ``A n = 0`` identically, ``|n|^2 = det(A A^T)``.

    (Laplace expansion of a 4x4 determinant with a repeated row; Cauchy-Binet.)
    """
    cols = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]]
    return ca.vertcat(*[(-1) ** i * ca.det(A[:, c]) for i, c in enumerate(cols)])


def null_motion(A, grad, gain: float):
    """Null motion ``gain * n (n . grad) / |n|^2``: ``grad`` projected on the null space of ``A``.

    Exactly torque free (``A n = 0``); near a singularity, where ``|n| -> 0``, the
    projector is regularised by a floor on ``|n|^2``.
    """
    n = null_vector(A)
    return gain * n * ca.dot(n, grad) / ca.fmax(ca.dot(n, n), _M_FLOOR)


def _options(name: str, options: dict) -> dict:
    defaults = STEERING_DEFAULTS[name]
    unknown = sorted(set(options) - set(defaults))
    if unknown:
        raise InputError(
            f"steering '{name}': unknown option(s) {', '.join(unknown)}; "
            f"expected some of {', '.join(defaults)}"
        )
    opts = {**defaults, **options}
    for key in ("lambda0", "mu", "epsilon0", "omega", "s_ref", "null_motion_gain"):
        if key in opts:
            v = opts[key]
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise InputError(f"steering '{name}' option {key} = {v!r}: expected a number >= 0")
    if "s_ref" in opts and opts["s_ref"] <= 0:
        raise InputError(f"steering '{name}' option s_ref = {opts['s_ref']}: expected > 0")
    if "phases" in opts:
        ph = np.asarray(opts["phases"], dtype=float)
        if ph.shape != (3,) or not np.all(np.isfinite(ph)):
            raise InputError(f"steering '{name}' option phases: expected 3 angles in rad")
        opts["phases"] = tuple(ph.tolist())
    if opts["h0_scale"] is not None and not (
        isinstance(opts["h0_scale"], (int, float)) and opts["h0_scale"] > 0
    ):
        raise InputError(f"steering '{name}' option h0_scale = {opts['h0_scale']!r}: expected > 0")
    if opts["null_motion_gain"] > 0:
        if opts["skew"] is None:
            raise InputError(
                f"steering '{name}': null_motion_gain > 0 needs the option skew (rad), "
                "to differentiate m(delta)"
            )
        opts["skew"] = check_skew(opts["skew"], f"steering '{name}' option skew")
    elif opts["skew"] is not None:
        opts["skew"] = check_skew(opts["skew"], f"steering '{name}' option skew")
    return opts


def _build(name: str, **options) -> ca.Function:
    """One factory for the four laws (see the module docstring)."""
    o = _options(name, options)
    A = ca.SX.sym("A", 3, 4)
    h_dot = ca.SX.sym("h_dot", 3)
    delta = ca.SX.sym("delta", 4)
    t = ca.SX.sym("t")
    scale = h0_scale_of(A) if o["h0_scale"] is None else o["h0_scale"]
    An = A / scale  # normalised Jacobian (seed 001 eq. 15)
    hn = h_dot / scale
    Mn = ca.mtimes(An, An.T)
    if name == "mp":
        dd = moore_penrose(A, h_dot)  # seed 001 eq. 16
    else:
        lam = o["lambda0"] * ca.exp(-o["mu"] * ca.det(Mn))  # lambda(m) = lambda0 exp(-mu m^2)
        if name == "sr":
            E = ca.DM.eye(3)
        elif name == "gsr":
            E = ca.DM.eye(3) + wie_dither(t, o["epsilon0"], o["omega"], o["phases"])
        else:  # sda
            E = sda_weight(Mn, o["s_ref"]) + wie_dither(t, o["epsilon0"], o["omega"], o["phases"])
        dd = sr_inverse(An, hn, lam, E)
    if o["null_motion_gain"] > 0:
        An_d = jacobian_normalised(delta, o["skew"])  # seed 001 eq. 15 via CasADi
        det_d = ca.det(ca.mtimes(An_d, An_d.T))
        # grad m = grad(m^2) / (2 m), exact from CasADi; the floor keeps m = 0 finite
        grad_m = ca.gradient(det_d, delta) / (2 * ca.sqrt(ca.fmax(det_d, _M_FLOOR)))
        dd = dd + null_motion(An, grad_m, o["null_motion_gain"])
    return ca.Function(
        f"steer_{name}", [A, h_dot, delta, t], [dd],
        ["A", "h_dot", "delta", "t"], ["delta_dot"],
    )  # fmt: skip


def _mp(**options) -> ca.Function:
    """Moore-Penrose pseudo-inverse (seed 001 eq. 16); options: null motion only."""
    return _build("mp", **options)


def _sr(**options) -> ca.Function:
    """Singularity-robust inverse with ``lambda = lambda0 exp(-mu m^2)``."""
    return _build("sr", **options)


def _gsr(**options) -> ca.Function:
    """Generalised SR inverse with Wie's (2005) deterministic off-diagonal dither."""
    return _build("gsr", **options)


def _sda(**options) -> ca.Function:
    """Singular-direction avoidance (Ford & Hall 2000) with Wie's dither."""
    return _build("sda", **options)


#: Steering-law factories by CLI name; each returns a CasADi Function.
STEERING_LAWS = {"mp": _mp, "sr": _sr, "gsr": _gsr, "sda": _sda}


def steering_function(name: str, **options) -> ca.Function:
    """The steering law ``name`` (see :data:`STEERING_LAWS`) as a CasADi Function.

    Parameters
    ----------
    name : {"mp", "sr", "gsr", "sda"}
        Law.
    **options
        See :data:`STEERING_DEFAULTS`: ``lambda0`` (-), ``mu`` (-), ``epsilon0`` (-),
        ``omega`` (rad/s), ``phases`` (rad), ``s_ref`` (-), ``null_motion_gain``
        (rad/s per unit of ``m``), ``skew`` (rad), ``h0_scale`` (N m s; default:
        inferred from ``A``).

    Returns
    -------
    casadi.Function
        ``(A[3x4], h_dot[3], delta[4], t) -> delta_dot[4]`` (rad/s).
    """
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
    if mode not in ("scale", "clip"):
        raise InputError(f"rate limiting mode '{mode}': expected 'scale' or 'clip'")
    if limit == float("inf"):
        return dd
    if mode == "scale":
        peak = ca.mmax(ca.fabs(dd))
        return ca.if_else(peak > limit, dd * (limit / peak), dd)  # seed 001 eq. 4
    return ca.fmin(ca.fmax(dd, -limit), limit)
