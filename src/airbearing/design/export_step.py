"""The step of a discrete Controller for C: ``(y, r, x, gains) -> (u, x_next)`` and its entries.

:class:`ExportSpec` holds the step (a CasADi Function built from the Controller's own) with
its measurements, references, states and commands as :class:`Signal` (log column, unit,
description, from :data:`COLUMNS`); :func:`controller_step` builds it for any Controller.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from airbearing.design.controller import Controller
from airbearing.errors import InputError
from airbearing.models.model import Model

#: Log column -> (unit, description) of everything an exported step reads or writes.
COLUMNS = {
    "qw": ("-", "measured attitude quaternion, scalar part (body -> lab)"),
    "qx": ("-", "measured attitude quaternion, x"),
    "qy": ("-", "measured attitude quaternion, y"),
    "qz": ("-", "measured attitude quaternion, z"),
    "yaw": ("rad", "measured yaw about lab z"),
    "wx": ("rad/s", "measured angular rate, body x"),
    "wy": ("rad/s", "measured angular rate, body y"),
    "wz": ("rad/s", "measured angular rate, body z"),
    "gx": ("-", "measured gravity direction, body x (unit vector, down)"),
    "gy": ("-", "measured gravity direction, body y"),
    "gz": ("-", "measured gravity direction, body z"),
    "d1": ("rad", "measured gimbal angle 1"),
    "d2": ("rad", "measured gimbal angle 2"),
    "d3": ("rad", "measured gimbal angle 3"),
    "d4": ("rad", "measured gimbal angle 4"),
    "dd1": ("rad/s", "commanded gimbal rate 1, after the rate limit"),
    "dd2": ("rad/s", "commanded gimbal rate 2, after the rate limit"),
    "dd3": ("rad/s", "commanded gimbal rate 3, after the rate limit"),
    "dd4": ("rad/s", "commanded gimbal rate 4, after the rate limit"),
    "yaw_ref": ("rad", "commanded yaw"),
    "qc_w": ("-", "commanded attitude quaternion, scalar part"),
    "qc_x": ("-", "commanded attitude quaternion, x"),
    "qc_y": ("-", "commanded attitude quaternion, y"),
    "qc_z": ("-", "commanded attitude quaternion, z"),
    "motor1": ("m", "stepper target of slider 1 (travel, step and speed limits applied)"),
    "motor2": ("m", "stepper target of slider 2 (travel, step and speed limits applied)"),
    "motor3": ("m", "stepper target of slider 3 (travel, step and speed limits applied)"),
    "mx": ("A m^2", "commanded magnetorquer dipole, body x, after saturation"),
    "my": ("A m^2", "commanded magnetorquer dipole, body y, after saturation"),
    "mz": ("A m^2", "commanded magnetorquer dipole, body z, after saturation"),
}


@dataclass(frozen=True)
class Signal:
    """One entry of ``y``, ``r``, ``x`` or ``u``: a name (the log column for y, r, u), a
    unit and a short description."""

    name: str
    unit: str
    description: str

    def to_json(self) -> dict:
        return {"name": self.name, "unit": self.unit, "description": self.description}


@dataclass(frozen=True, eq=False)
class ExportSpec:
    """A controller ready for C: ``step(y, r, x, gains) -> (u, x_next)`` and its entries.

    Attributes
    ----------
    function : casadi.Function
        The step, built from the Controller's own Function (SX, dense columns).
    y, r, x, u : tuple of Signal
    x0 : ndarray
        The state ``NAME_init`` writes (the simulation's ``c0``, counter 0).
    gains : dict
        Gain name -> value, SI (the ``static const`` array of ``NAME.c``).
    dt : float
        s, the sample time.
    meta : dict
        Testbed, loop and options, written to ``NAME.json``.

    Examples
    --------
    Seed 001's attitude controller of the yaw CMG testbed, ready for C:

    >>> import airbearing as ab
    >>> spec = ab.export_spec(ab.load_testbed("cmg-yaw"), "attitude")
    >>> [s.name for s in spec.y], [s.name for s in spec.r], [s.name for s in spec.u]
    (['wz', 'd1', 'd2', 'd3', 'd4'], ['yaw_ref'], ['dd1', 'dd2', 'dd3', 'dd4'])
    >>> spec.dt, spec.gains, len(spec.x)  # s; the controller's state entries
    (0.05, {'K_p': 6.0, 'K_i': 0.001, 'K_w': 6.0}, 10)
    """

    function: ca.Function = field(repr=False)
    y: tuple
    r: tuple
    x: tuple
    u: tuple
    x0: np.ndarray = field(repr=False)
    gains: dict
    dt: float
    meta: dict = field(default_factory=dict)


def _signals(names, table=COLUMNS) -> tuple:
    return tuple(Signal(n, *table.get(n, ("-", n))) for n in names)


def controller_step(
    model: Model,
    controller: Controller,
    *,
    u_names,
    r_names=None,
    ref_of=None,
    x_names=None,
) -> tuple[ca.Function, tuple, tuple, tuple, np.ndarray]:
    """The step ``(y, r, x, gains) -> (u, x_next)`` of any discrete Controller.

    Parameters
    ----------
    model : Model
    controller : Controller
    u_names : sequence of str
        The commands, each a name of ``model.u_names`` or of ``controller.extra_names``
        (the log column it is written to).
    r_names : sequence of str, optional
        The references as logged; default ``controller.ref_names``.
    ref_of : callable, optional
        ``ref_of(r) -> ref``: the controller's reference from ``r`` (SX); default identity.
    x_names : sequence of Signal, optional
        Names of the controller state ``c`` (default ``c0 .. c<n-1>``).

    Returns
    -------
    (Function, y names, r names, x Signals, x0)
        ``y`` holds only the measurements the controller depends on (structurally);
        ``x`` ends with a sample counter ``k`` when the law depends on time
        (``t = k dt``, as the simulation's ``t_k``).
    """
    dt = model.testbed.sensors.dt
    nc = controller.c0.size
    r_names = tuple(controller.ref_names if r_names is None else r_names)
    y_all = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", nc)
    r = ca.SX.sym("r", len(r_names))
    g = ca.SX.sym("gains", controller.gains.size)
    k = ca.SX.sym("k")
    ref = r if ref_of is None else ref_of(r)
    u, c_next, extra = controller.function(y_all, c, ref, g, k * dt)
    outs = []
    for n in u_names:
        if n in model.u_names:
            outs.append(u[model.u_names.index(n)])
        elif n in controller.extra_names:
            outs.append(extra[controller.extra_names.index(n)])
        else:
            raise InputError(f"command '{n}': not an input nor a logged quantity of the controller")
    u_out = ca.vertcat(*outs)
    both = ca.vertcat(u_out, c_next)
    used = [i for i in range(model.ny) if ca.depends_on(both, y_all[i])]
    timed = bool(ca.depends_on(both, k))
    states = list(x_names) if x_names is not None else list(_signals([f"c{i}" for i in range(nc)]))
    if len(states) != nc:
        raise ValueError(f"{len(states)} state names for {nc} controller states")
    x = ca.vertcat(c, k) if timed else c
    x_next = ca.vertcat(c_next, k + 1) if timed else c_next
    x0 = np.concatenate([controller.c0, [0.0]]) if timed else np.asarray(controller.c0, float)
    if timed:
        states.append(Signal("k", "-", "samples since NAME_init (the law's time is k dt)"))
    y_used = ca.vertcat(*[y_all[i] for i in used])
    y_in = ca.SX.sym("y", len(used))
    u_out, x_next = ca.substitute([u_out, x_next], [y_used], [y_in]) if used else (u_out, x_next)
    fn = ca.Function(
        "step", [y_in, r, x, g], [u_out, x_next], ["y", "r", "x", "gains"], ["u", "x_next"]
    )
    return fn, tuple(model.y_names[i] for i in used), r_names, tuple(states), x0
