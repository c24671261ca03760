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
    """A discrete controller block and the names and defaults that go with it.

    Attributes
    ----------
    name : str
        What it is (``"cmg_attitude_mp"``, ``"open_loop"`` ...).
    function : casadi.Function
        ``(y, c, ref, gains, t) -> (u, c_next, extra)`` (module doc), one sample.
    c0 : numpy.ndarray
        The controller state at the start of a run.
    gains : numpy.ndarray
        The tunable numbers, in the order of ``gain_names`` (their units are the law's).
    gain_names : tuple of str
    ref_names : tuple of str
        The entries of the reference (a quaternion ``qc_w .. qc_z`` for an attitude loop).
    extra_names : tuple of str
        The quantities it logs each sample.

    Examples
    --------
    >>> import airbearing as ab
    >>> controller = ab.cmg_attitude_controller(ab.build_model("cmg-yaw"))
    >>> controller.name, controller.gain_names, controller.gains.tolist()
    ('cmg_attitude_mp', ('K_p', 'K_i', 'K_w'), [6.0, 0.001, 6.0])
    >>> controller.with_gains(K_p=2.0).gains.tolist()
    [2.0, 0.001, 6.0]
    """

    name: str
    function: ca.Function
    c0: np.ndarray
    gains: np.ndarray
    gain_names: tuple
    ref_names: tuple
    extra_names: tuple = ()

    def with_gains(self, **values) -> Controller:
        """A copy with some gains replaced by name.

        Parameters
        ----------
        **values : float
            Gain name (:attr:`gain_names`) -> value, in the law's units.

        Returns
        -------
        Controller
        """
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

    Parameters
    ----------
    model : Model
        The plant.
    u : array_like
        Shape (nu,), the input in the units of ``model.u_names`` (rad/s for gimbal rates,
        N m for torques, m for sliders, A m^2 for dipoles).

    Returns
    -------
    Controller
        Named ``"open_loop"``, its gains ``u``.

    Examples
    --------
    A constant 1e-4 N m torque about z on the yaw CMG testbed (``J_zz`` = 0.00283 kg m^2)
    for 2 s, noise-free: the rate grows as ``tau t / J_zz``:

    >>> import numpy as np
    >>> import airbearing as ab
    >>> model = ab.build_model("cmg-yaw")
    >>> u = np.zeros(model.nu)
    >>> u[model.index("tau_z", "u")] = 1e-4
    >>> run = ab.simulate(model, ab.constant_input(model, u), duration=2.0, x0=model.x0(),
    ...                   noise=False)
    >>> round(float(run.log.rates()[-1, 0]), 4), round(1e-4 * 1.95 / 0.00283, 4)  # rad/s
    (0.0689, 0.0689)
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
