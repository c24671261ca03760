"""The linear model of a loop's controller: the exact Jacobians (``ca.jacobian``) of the
very CasADi Function the nonlinear simulation runs, about the trim measurement, with the
gains an input of the Jacobian Function (built once, evaluated for any gains), and the
controller's state that holds the trim (:func:`trim_state`).

:func:`linear_controller` builds them once for a loop's controller, trim and channels and
keeps them in a small cache.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.controller import Controller
from airbearing.design.linearise import TrimPoint
from airbearing.errors import InputError
from airbearing.models.model import Model
from airbearing.models.structure_cache import structure_key

__all__ = ["LinearController", "controller_key", "linear_controller", "trim_state"]

_TRIM_TOL = 1e-9  # relative residual accepted for the controller's trim state


@dataclass(frozen=True, eq=False)
class LinearController:
    """Jacobians of a discrete Controller about its trim, with the gains as an input."""

    fn: ca.Function  # (gains, c_trim) -> (A, B, C, D): x = c, inputs [y_used; ref], outputs u_ch
    trim_fn: ca.Function  # gains -> (residual Jacobian, residual) to solve for c_trim
    n_c: int
    c0: np.ndarray  # the controller's initial state: the start of the trim solve
    inputs: tuple  # measurement names used, then reference names
    outputs: tuple  # channel names


def _build_linear_controller(
    model: Model, controller: Controller, trim_point: TrimPoint, channels, ref_expr, ref_names
) -> LinearController:
    """Jacobians of ``controller.function`` about the trim measurement, gains symbolic."""
    y_star = np.asarray(model.h(trim_point.x, trim_point.u, trim_point.p)).ravel()
    nc = controller.c0.size
    c = ca.SX.sym("c", nc)
    g = ca.SX.sym("gains", controller.gains.size)
    y = ca.SX.sym("y", model.ny)
    r = ca.SX.sym("r", len(ref_names))
    ref = ref_expr(r)
    u, c_next, _ = controller.function(y, c, ref, g, 0.0)
    ch_idx = model.index(list(channels), "u")
    u_ch = u[ch_idx]
    at_y, at_r = ca.DM(y_star), ca.DM.zeros(len(ref_names))
    # which measurements does the controller use at all? (structural)
    # which measurements does the controller use at the trim? (numeric pattern, generic gains)
    Jy = ca.Function("jy", [y, c, g, r], [ca.jacobian(ca.vertcat(u_ch, c_next), y)])
    Jy = np.asarray(
        Jy(y_star, controller.c0, np.ones(controller.gains.size), np.zeros(len(ref_names)))
    )
    used = [i for i in range(model.ny) if np.any(Jy[:, i] != 0)]
    yin = y[used]
    inputs = ca.vertcat(yin, r)
    mats = [
        ca.jacobian(c_next, c),
        ca.jacobian(c_next, inputs),
        ca.jacobian(u_ch, c),
        ca.jacobian(u_ch, inputs),
    ]
    mats = ca.substitute(mats, [y, r], [at_y, at_r])
    fn = ca.Function("lin_ctrl", [g, c], mats, ["gains", "c"], ["A", "B", "C", "D"])
    u_trim = ca.DM(trim_point.u[ch_idx])
    res = ca.vertcat(c_next - c, u_ch - u_trim)
    res = ca.substitute(res, ca.vertcat(y, r), ca.vertcat(at_y, at_r))
    trim_fn = ca.Function("ctrl_trim", [g, c], [ca.jacobian(res, c), res])
    return LinearController(
        fn,
        trim_fn,
        nc,
        np.asarray(controller.c0, float),
        tuple(model.y_names[i] for i in used) + tuple(ref_names),
        tuple(channels),
    )


def trim_state(lc: LinearController, gains: np.ndarray, c0=None, *, kind="balancing") -> np.ndarray:
    """Controller state holding the trim: ``c_next = c`` and ``u = u_trim`` (Newton, exact).

    ``kind`` (the loop's, "balancing" or "attitude") only words the error when none exists.
    """
    c = np.array(lc.c0 if c0 is None else c0, dtype=float)
    scale = 1.0
    for _ in range(4):  # the equations are linear in c for these laws; a few steps at most
        J, r = (np.asarray(v, float) for v in lc.trim_fn(gains, c))
        r = r.ravel()
        scale = max(np.abs(r).max(), 1e-12) if scale == 1.0 else scale
        if np.abs(r).max() <= _TRIM_TOL * max(scale, 1.0):
            return c
        c = c - np.linalg.lstsq(J, r, rcond=None)[0]
    r = np.asarray(lc.trim_fn(gains, c)[1]).ravel()
    if np.abs(r).max() > 1e-7 * max(scale, 1.0):
        why = (
            "the balancing loop needs integral action (K_dK_i > 0)"
            if kind == "balancing"
            else "a constant input at the trim (a gyro bias, a constant torque) moves the "
            "attitude loop's state without end, so there is no trim to linearise about"
        )
        raise InputError(
            "the controller cannot hold the trim with these gains (residual "
            f"{np.abs(r).max():.3g}): {why}"
        )
    return c


#: The linear controllers built, by :func:`linear_controller`'s key (bounded).
_LC_CACHE: dict = {}
_LC_CACHE_SIZE = 32


def controller_key(ctl: Controller) -> tuple:
    """What decides a controller's linear model, as a hashable key.

    Parameters
    ----------
    ctl : Controller

    Returns
    -------
    tuple
        The SHA-256 of its serialised CasADi Function (the expressions and every number
        built into them: gains, slider matrix, field, options), its initial state, the
        number of its gains and its reference names.
    """
    text = ctl.function.serialize()
    return (
        hashlib.sha256(text.encode()).hexdigest(),
        np.asarray(ctl.c0, dtype=float).tobytes(),
        int(np.size(ctl.gains)),
        tuple(ctl.ref_names),
    )


def linear_controller(model, ctl, tp, channels, kind) -> LinearController:
    """The linear model of ``ctl`` about the trim ``tp``, broken at ``channels`` (cached).

    Parameters
    ----------
    model : Model
        The loop's plant.
    ctl : Controller
        The loop's controller (ideal actuators).
    tp : TrimPoint
        The trim.
    channels : sequence of str
        The actuator inputs the loop is broken at (``model.u_names``).
    kind : {"balancing", "attitude"}
        The loop: the attitude loop's references are the yaw (dof 1) or a rotation
        vector (dof 3) about the trim attitude, rad; the balancing loop has none.

    Returns
    -------
    LinearController

    Notes
    -----
    Cached by what decides the result: the model's structure
    (:func:`~airbearing.models.structure_cache.structure_key`; the trim's ``p`` gives its
    values), the controller (:func:`controller_key`), the channels and the trim's state,
    input and parameters. Not by names: two controllers of one name with other gains
    baked in, or another structure, have other linear models.
    """
    key = (
        structure_key(model),
        kind,
        controller_key(ctl),
        tuple(channels),
        *(np.asarray(v, dtype=float).tobytes() for v in (tp.x, tp.u, tp.p)),
    )
    hit = _LC_CACHE.get(key)
    if hit is not None:
        return hit
    if kind == "attitude" and model.dof == 1:
        names = ("yaw_ref",)
        yaw0 = float(tp.x[0])

        def ref_expr(r):
            return quat.from_yaw(yaw0 + r[0])
    elif kind == "attitude":
        names = ("ref_x", "ref_y", "ref_z")
        q0 = ca.DM(tp.x[0:4])

        def ref_expr(r):
            return quat.qmul(q0, quat.qexp(r))
    else:
        names = ()

        def ref_expr(r):
            return ca.SX(0, 1)

    lc = _build_linear_controller(model, ctl, tp, channels, ref_expr, names)
    if len(_LC_CACHE) > _LC_CACHE_SIZE:
        _LC_CACHE.clear()
    _LC_CACHE[key] = lc
    return lc
