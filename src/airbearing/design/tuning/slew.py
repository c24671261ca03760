"""Seed 001's 180 deg manoeuvre on the linear discrete loop with the gimbal rates limited.

A large slew differs from the linear step: the gimbal rates saturate (seed 001 eq. 4), the
body turns at a bounded rate, and the integral winds up meanwhile; after the slew the
wound-up integral leaves an error of about ``2 (K_i / K_p) int(q_v dt)`` that decays at
the integral pole, ``K_i / K_p`` rad/s.
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np

from airbearing.design.loops import Loop
from airbearing.models.loop import ExpandedLoop

__all__: list[str] = []

_SLEW_DEG = 180.0  # deg, seed 001 Sec. 5 (Tables 6-7): the 180 deg manoeuvre
_A_ERR_DEG = 1.5  # deg, seed 001 Table 6: steady once the error stays below a_err ...
_T_SS = 3.0  # s, ... for t_ss (Table 6)
_SLEW_HORIZON = 60.0  # s of the rate-limited slew (seed 001: steady by about 20 s)


def _slew_response(P, K, Dl, nmeas: int, nch: int, iy: int, limit: float, dt: float):
    """Seed 001's 180 deg manoeuvre on the linear discrete loop with the gimbal rates
    limited as the controller limits them (seed 001 eq. 4: all four scaled together).

    ``P`` (plant: inputs channels then disturbances, outputs the used measurements then
    the attitude ``iy``), ``K`` (controller: measurements then references in, gimbal-rate
    commands out) and ``Dl`` (the delay) as matrices. Returns ``(overshoot % of the slew,
    settling time s)``: settled once the error stays within a_err = 1.5 deg (Table 6) to
    the end of the run, inf when it is outside it in the last t_ss = 3 s.

    The saturation makes the integral wind up while the body turns at its limited rate;
    the quaternion error's own saturation (``sin`` of half the angle) and the gimbal
    angles' drift are left out. On cmg-yaw the settling times agree with the nonlinear
    simulation's (``airbearing.slew``, ideal sensors) to 0.4 s: 7.0 and 7.3 s with seed
    001's Table 6 gains, 29.5 and 29.4 s with gains whose integral winds up.
    """
    Ap, Bp, Cp, Dp = P
    Ac, Bc, Cc, Dc = K
    Ad, Bd, Cd, _ = Dl
    step = math.radians(_SLEW_DEG)
    r = np.zeros(Bc.shape[1] - nmeas)
    r[0] = step
    npl, nc, nd = Ap.shape[0], Ac.shape[0], Ad.shape[0]
    ip, ic, idl = slice(0, npl), slice(npl, npl + nc), slice(npl + nc, npl + nc + nd)
    # the loop in the state x = [plant, controller, delay]: the channels u = Cd x_d (one
    # sample of delay or more: no direct path), the measurements y = Cy x, the commands
    # v = Cv x + dcr before the limit, x+ = F x + G v + g
    Cy = np.zeros((Cp.shape[0], npl + nc + nd))
    Cy[:, ip], Cy[:, idl] = Cp, Dp[:, :nch] @ Cd
    Bcy, Dcy = Bc[:, :nmeas], Dc[:, :nmeas]
    Cv = Dcy @ Cy[:nmeas]
    Cv[:, ic] += Cc
    F = np.zeros((npl + nc + nd,) * 2)
    F[ip, ip], F[ip, idl] = Ap, Bp[:, :nch] @ Cd
    F[ic] = Bcy @ Cy[:nmeas]
    F[ic, ic] += Ac
    F[idl, idl] = Ad
    G = np.zeros((npl + nc + nd, Bd.shape[1]))
    G[idl] = Bd
    g = np.zeros(npl + nc + nd)
    g[ic] = Bc[:, nmeas:] @ r
    n = int(round(_SLEW_HORIZON / dt))
    rollout = _rollout(F.shape[0], Cv.shape[0])
    _, y = rollout(np.zeros(F.shape[0]), n, F, G, g, Cv, Dc[:, nmeas:] @ r, Cy[iy : iy + 1], limit)
    err = y[0] - step
    overshoot = max(0.0, 100.0 * float(err.max()) / step)
    out = np.nonzero(np.abs(err) > math.radians(_A_ERR_DEG))[0]
    if out.size and out[-1] >= n - int(round(_T_SS / dt)):
        return overshoot, math.inf
    return overshoot, float((out[-1] + 1) * dt) if out.size else 0.0


@lru_cache(maxsize=16)
def _rollout(nx: int, nv: int) -> ExpandedLoop:
    """The rate-limited loop as a CasADi rollout (built once per size, the matrices as
    inputs): ``(x0, n, F, G, g, Cv, dcr, cy, limit) -> (X, y)``, the states after each
    sample and the attitude ``cy x`` at each sample (before its step)."""
    x = ca.SX.sym("x", nx)
    F, G, g = ca.SX.sym("F", nx, nx), ca.SX.sym("G", nx, nv), ca.SX.sym("g", nx)
    Cv, dcr, cy = ca.SX.sym("Cv", nv, nx), ca.SX.sym("dcr", nv), ca.SX.sym("cy", 1, nx)
    limit = ca.SX.sym("limit")
    v = Cv @ x + dcr
    v = v * ca.fmin(1, limit / ca.mmax(ca.fabs(v)))  # seed 001 eq. 4: all scaled together
    one = ca.Function("slew_step", [x, F, G, g, Cv, dcr, cy, limit], [F @ x + G @ v + g, cy @ x])
    return ExpandedLoop(one)


def slew_limit(loop: Loop) -> float | None:
    """The channel limit the rate-limited slew scales the commands by: a CMG's gimbal-rate
    limit (rad/s), torque-commanded wheels' ``max_torque`` (N m, the wheel controller
    scales its torques the same way); None for other loops and for speed-commanded wheels
    (their torque limit acts inside the controller, before the target speed)."""
    if loop.kind != "attitude":
        return None
    if loop.wheels and loop.model.testbed.wheels.command != "torque":
        return None
    limit = loop.channel_limit
    return limit if math.isfinite(limit) else None


def _loop_slew(loop: Loop):
    """:func:`_slew_response` on ``loop``'s python-control pieces (attitude loops with a
    limit on their channels, :func:`slew_limit`; None otherwise)."""
    limit = slew_limit(loop)
    if limit is None:
        return None
    meas = list(loop.used_measurements())
    target = loop.default_outputs()[0]
    plant = loop.plant(discrete=True, outputs=[target])
    iy = list(plant.output_labels).index(target)
    K = loop.controller_ss(discrete=True)
    mats = [
        tuple(np.asarray(m, float) for m in (x.A, x.B, x.C, x.D)) for x in (plant, K, loop.delay())
    ]
    return _slew_response(*mats, len(meas), len(loop.channels), iy, limit, loop.dt)
