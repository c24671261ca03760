"""A controller with samples of computation delay between its command and the plant, for
nonlinear runs that match the discrete linear loop (:mod:`airbearing.design.loops`)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing.design.controller import Controller
from airbearing.models.model import Model

__all__ = ["with_delay"]


def with_delay(controller: Controller, model: Model, samples: int = 1, u_hold=None) -> Controller:
    """The controller with ``samples`` of computation delay: its input reaches the plant later.

    The delayed commands live in the controller state; before the first computed command
    arrives the plant gets ``u_hold`` (default zeros). For nonlinear runs that match the
    discrete linear loop.
    """
    if samples == 0:
        return controller
    nu = model.nu
    fn = controller.function
    nc = controller.c0.size
    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", nc + nu * samples)
    ref = ca.SX.sym("ref", len(controller.ref_names))
    g = ca.SX.sym("gains", controller.gains.size)
    t = ca.SX.sym("t")
    u, c_next, extra = fn(y, c[:nc], ref, g, t)
    buf = c[nc:]
    u_out = buf[0:nu]
    buf_next = ca.vertcat(buf[nu:], u)
    f = ca.Function(
        f"{controller.name}_delayed",
        [y, c, ref, g, t],
        [u_out, ca.vertcat(c_next, buf_next), extra],
        ["y", "c", "ref", "gains", "t"],
        ["u", "c_next", "extra"],
    )
    hold = np.zeros(nu) if u_hold is None else np.asarray(u_hold, float)
    return Controller(
        controller.name + "_delayed",
        f,
        np.concatenate([controller.c0, np.tile(hold, samples)]),
        controller.gains,
        controller.gain_names,
        controller.ref_names,
        controller.extra_names,
    )
