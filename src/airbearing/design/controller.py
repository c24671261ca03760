"""The discrete-time controller interface shared by every closed loop.

A controller is a CasADi Function

``(y, c, ref, gains, t) -> (u, c_next, extra)``

with ``y`` the noisy measurement (a Model's ``y_names``), ``c`` the controller
state, ``ref`` the reference, ``gains`` the tunable numbers, ``t`` the sample
time (s), ``u`` the plant input held over the next sample (the Model's
``u_names``), and ``extra`` named quantities worth logging. Because it is a
CasADi Function, a whole closed loop compiles into one rollout.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

__all__ = ["Controller", "constant_input"]


@dataclass(frozen=True, eq=False)
class Controller:
    """A discrete controller block and the names and defaults that go with it."""

    name: str
    function: ca.Function
    c0: np.ndarray
    gains: np.ndarray
    gain_names: tuple
    ref_names: tuple
    extra_names: tuple = ()

    def with_gains(self, **values) -> Controller:
        """A copy with some gains replaced by name."""
        g = self.gains.copy()
        for k, v in values.items():
            g[self.gain_names.index(k)] = v
        return Controller(
            self.name,
            self.function,
            self.c0,
            g,
            self.gain_names,
            self.ref_names,
            self.extra_names,
        )


def constant_input(model, u: np.ndarray) -> Controller:
    """No feedback: the input ``u`` (the Model's ``u_names``) is held for the whole run.

    ``u`` is passed as the controller's gains, so one compiled loop serves any value.
    """
    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", 0)
    ref = ca.SX.sym("ref", 0)
    g = ca.SX.sym("u_const", model.nu)
    t = ca.SX.sym("t")
    fn = ca.Function(
        "open_loop",
        [y, c, ref, g, t],
        [g, c, ca.SX(0, 1)],
        ["y", "c", "ref", "gains", "t"],
        ["u", "c_next", "extra"],
    )
    return Controller("open_loop", fn, np.zeros(0), np.asarray(u, float), tuple(model.u_names), ())
