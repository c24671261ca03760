"""One feedback loop as python-control models: :class:`Loop` (plant, controller, trim,
gains) and the gains' check (:func:`gain_dict`). The package's two loops are built by
:mod:`airbearing.design.loops`.

Time bases
    *discrete*: the plant sampled with a zero-order hold at the sensor rate, one sample of
    computation delay on every actuator channel, the controller as implemented;
    *continuous*: the design model without sampling or delay, the controller mapped to
    continuous time by the inverse bilinear (Tustin) transform.

Every loop is broken at the actuator input: :meth:`Loop.loop_transfer` gives the
loop-at-a-time transfer ``L_j`` of one actuator channel with the others closed, or the
MIMO ``L`` with all channels open (for multi-loop disk margins). The sign convention is
negative feedback: the closed loop is stable iff ``1 + L`` has no unstable zeros, and
``S = 1 / (1 + L)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from airbearing.design import _control as ct
from airbearing.design.controller import Controller
from airbearing.design.linear_controller import LinearController, trim_state
from airbearing.design.linearise import (
    TrimPoint,
    d2c_bilinear,
    delay_system,
    linearisation,
    prune_states,
)
from airbearing.design.momentum_poles import body_state_mask, without_momentum_poles
from airbearing.design.wheels import has_wheels
from airbearing.errors import InputError
from airbearing.models.model import Model

__all__ = ["Loop", "gain_dict"]


@dataclass(frozen=True, eq=False)
class Loop:
    """One feedback loop: plant, controller, trim, gains and the python-control models.

    Build with :func:`~airbearing.design.loops.balancing_loop` or
    :func:`~airbearing.design.loops.attitude_loop`. A Loop is immutable;
    :meth:`with_gains` and :meth:`with_params` give variants that share the compiled
    Jacobian Functions.

    Attributes
    ----------
    kind : {"balancing", "attitude"}
    name : str
        ``"balancing-mixed"``, ``"balancing-mechanical"`` or ``"attitude"``.
    model : Model
    trim : TrimPoint
    controller : Controller
        The nonlinear discrete controller (ideal actuators) the linear model comes from.
    gains : dict
        Gain name -> value.
    channels : tuple of str
        Actuator inputs the loop is broken at (``s1 s2``, ``mx my``, ``dd1..dd4``,
        ``wc1..``).
    references : tuple of str
        Reference inputs of the closed loop (``yaw_ref`` for the attitude loop).
    disturbances : tuple of str
        Disturbance torques entering the plant.
    p : ndarray
        Physical parameters of the plant (the controller keeps its nominal knowledge).
    delay_samples : int
        Computation delay of the discrete loop, samples.
    notes : tuple of str
        What the reader of a report should know about this loop (said in words).

    Examples
    --------
    Seed 001's attitude loop of the yaw CMG testbed, broken at the four gimbal-rate
    commands:

    >>> import airbearing as ab
    >>> loop = ab.make_loop(ab.load_testbed("cmg-yaw"), "attitude")
    >>> loop
    Loop(kind='attitude', name='attitude', gains={'K_p': 6.0, 'K_i': 0.001, 'K_w': 6.0},
         channels=('dd1', 'dd2', 'dd3', 'dd4'), delay_samples=1)
    >>> loop.dt, loop.channel_quantity, round(loop.channel_limit, 3)  # s; rad/s
    (0.05, 'gimbal rate (rad/s)', 1.126)
    >>> loop.used_measurements(), loop.default_outputs()
    (('wz',), ['true_yaw', 'true_wz'])
    >>> closed = loop.closed_loop()  # python-control StateSpace, discrete
    >>> closed.input_labels, bool(abs(loop.stability_poles()).max() < 1)
    (['yaw_ref', 'tau_z'], True)
    >>> loop.with_gains({"K_p": 3.0, "K_i": 0.001, "K_w": 6.0}).gain_vector.tolist()
    [3.0, 0.001, 6.0]
    """

    kind: str
    name: str
    model: Model = field(repr=False)
    trim: TrimPoint = field(repr=False)
    controller: Controller = field(repr=False)
    gains: dict
    channels: tuple
    references: tuple = field(repr=False)
    disturbances: tuple = field(repr=False)
    p: np.ndarray = field(repr=False)
    delay_samples: int
    _lin_ctrl: LinearController = field(repr=False)
    notes: tuple = field(default=(), repr=False)

    @property
    def dt(self) -> float:
        """Sample interval of the discrete loop, s (``1 / sensors.rate``)."""
        return self.model.testbed.sensors.dt

    @property
    def wheels(self) -> bool:
        """True for the attitude loop of a reaction-wheel rig."""
        return self.kind == "attitude" and has_wheels(self.model.testbed)

    @property
    def channel_limit(self) -> float:
        """The limit of each actuator channel: the gimbal-rate limit (rad/s) of a CMG, the
        motor torque limit (N m) of wheels (of speed-commanded ones, the torque their
        driver gives, ``Iw (wc - W) / speed_loop_tau``); inf for the balancing loop."""
        tb = self.model.testbed
        if self.kind != "attitude":
            return math.inf
        if self.wheels:
            return tb.wheels.max_torque
        return tb.cmg.max_gimbal_rate

    @property
    def channel_quantity(self) -> str:
        """What an actuator channel carries, with its unit (the actuator-peak check's name)."""
        if self.wheels:
            return "wheel torque (N m)"
        return "gimbal rate (rad/s)"

    @property
    def gain_vector(self) -> np.ndarray:
        """The gains in the controller's order (``controller.gain_names``), SI."""
        return np.array([self.gains[k] for k in self.controller.gain_names], dtype=float)

    # ---------------------------------------------------------------- variants

    def with_gains(self, gains) -> Loop:
        """The same loop with other gains.

        Parameters
        ----------
        gains : mapping or sequence of float
            Every gain by name, or all of them in ``controller.gain_names`` order (SI).

        Returns
        -------
        Loop

        Raises
        ------
        InputError
            A gain missing, unknown or not finite.
        """
        return replace(self, gains=gain_dict(self.controller.gain_names, gains))

    def with_params(self, p) -> Loop:
        """The same loop on a plant with parameters ``p`` (the controller is unchanged).

        Parameters
        ----------
        p : array_like
            Shape (n_p,), the Model's parameters (``model.p_names``, SI).

        Returns
        -------
        Loop

        Raises
        ------
        InputError
            ``p`` of the wrong shape.
        """
        p = np.asarray(p, dtype=float)
        if p.shape != (self.model.n_p,):
            raise InputError(f"parameters have shape {p.shape}, expected ({self.model.n_p},)")
        return replace(self, p=p)

    # ---------------------------------------------------------------- plant

    def _plant_full(self) -> ct.StateSpace:
        return linearisation(self.model).state_space(self.trim, self.p, name="plant")

    def used_measurements(self) -> tuple:
        """The measurements the controller reads (not its references).

        Returns
        -------
        tuple of str
            Names of ``model.y_names``.
        """
        return tuple(n for n in self._lin_ctrl.inputs if n not in self.references)

    def plant(self, *, discrete: bool = True, outputs=None) -> ct.StateSpace:
        """The linear plant from the actuator channels and disturbances.

        States not seen by the controller's measurements nor by ``outputs`` are pruned
        (e.g. the gimbal angles, or the yaw of a balancing platform: neutral modes the
        loop does not act on). Discrete: zero-order hold and ``delay_samples`` of delay on
        the channels, whose inputs are then named ``<channel>_cmd``.

        Parameters
        ----------
        discrete : bool
            Sampled at the loop's rate (zero-order hold), else continuous.
        outputs : sequence of str, optional
            Further outputs to keep (``true_*`` states).

        Returns
        -------
        control.StateSpace
        """
        full = self._plant_full()
        keep_out = list(self.used_measurements()) + [
            o for o in (outputs or []) if o not in self.used_measurements()
        ]
        ins = list(self.channels) + list(self.disturbances)
        sys = prune_states(full, keep_out, ins)
        states = list(sys.state_labels)  # indexing the outputs renames the states
        sys = sys[[list(sys.output_labels).index(o) for o in keep_out], :]
        idx = [list(full.input_labels).index(n) for n in ins]
        sys = ct.ss(
            sys.A,
            sys.B[:, idx],
            sys.C,
            sys.D[:, idx],
            states=states,
            inputs=ins,
            outputs=keep_out,
            name="plant",
        )
        if not discrete:
            return sys
        sysd = ct.sample_system(sys, self.dt, method="zoh", name="plant")
        return sysd

    def delay(self) -> ct.StateSpace:
        """``delay_samples`` of computation delay on each channel.

        Returns
        -------
        control.StateSpace
            Discrete, ``<ch>_cmd`` -> ``<ch>``.
        """
        return delay_system(self.channels, self.dt, self.delay_samples, suffix="_cmd")

    # ---------------------------------------------------------------- controller

    def controller_trim(self) -> np.ndarray:
        """Controller state at the trim (e.g. the integral holding the sliders), solved.

        Returns
        -------
        numpy.ndarray
            Shape of ``controller.c0``.
        """
        return trim_state(self._lin_ctrl, self.gain_vector, kind=self.kind)

    def controller_ss(self, *, discrete: bool = True) -> ct.StateSpace:
        """The linearised controller: inputs the used measurements and references,
        outputs ``<channel>_cmd``.

        Parameters
        ----------
        discrete : bool
            The sampled controller, else its bilinear (Tustin) continuous equivalent.

        Returns
        -------
        control.StateSpace
        """
        lc = self._lin_ctrl
        A, B, C, D = (np.asarray(m) for m in lc.fn(self.gain_vector, self.controller_trim()))
        ins = list(lc.inputs)
        outs = [f"{c}_cmd" for c in lc.outputs]
        states = [f"c{i}" for i in range(lc.n_c)]
        sysd = ct.ss(
            A, B, C, D, dt=self.dt, inputs=ins, outputs=outs, states=states, name="controller"
        )
        sysd = prune_states(sysd)
        if discrete:
            return sysd
        return d2c_bilinear(sysd)

    # ---------------------------------------------------------------- loops

    def _parts(self, discrete: bool, outputs=None, open_channels=()):
        plant = self.plant(discrete=discrete, outputs=outputs)
        ctrl = self.controller_ss(discrete=discrete)
        if discrete:
            dly = self.delay()
        else:
            n = len(self.channels)
            dly = ct.ss(
                [],
                [],
                [],
                np.eye(n),
                inputs=[f"{c}_cmd" for c in self.channels],
                outputs=list(self.channels),
                name="delay",
            )
        if open_channels:
            outs = [f"{c}_open" if c in open_channels else c for c in self.channels]
            dly = ct.ss(
                dly.A,
                dly.B,
                dly.C,
                dly.D,
                dt=dly.dt,
                inputs=list(dly.input_labels),
                outputs=outs,
                states=list(dly.state_labels),
                name="delay",
            )
        return plant, ctrl, dly

    def loop_transfer(self, channel: str | None = None, *, discrete: bool = True) -> ct.StateSpace:
        """Loop transfer at the actuator input, negative-feedback convention.

        ``channel`` given: the SISO loop-at-a-time ``L_j`` (the other channels closed);
        ``None``: the MIMO ``L`` with every channel open.

        Parameters
        ----------
        channel : str, optional
            One of :attr:`channels`.
        discrete : bool
            The sampled loop (with its delay), else the continuous design model.

        Returns
        -------
        control.StateSpace

        Raises
        ------
        InputError
            An unknown channel.
        """
        chans = list(self.channels) if channel is None else [channel]
        if channel is not None and channel not in self.channels:
            raise InputError(f"loop '{channel}': expected one of {', '.join(self.channels)}")
        plant, ctrl, dly = self._parts(discrete, open_channels=chans)
        refs = list(self.references)
        sys = ct.interconnect(
            [plant, ctrl, dly],
            inplist=chans + refs + list(self.disturbances),
            outlist=[f"{c}_open" for c in chans],
            check_unused=False,
            name="open_loop",
        )
        sys = sys[:, list(range(len(chans)))]
        L = -sys
        return ct.ss(
            L.A, L.B, L.C, L.D, dt=L.dt, inputs=chans, outputs=chans, name=f"L_{channel or 'all'}"
        )

    def axis_loop(self, *, discrete: bool = True) -> ct.StateSpace | None:
        """The single-axis loop of a yaw-only CMG testbed: ``trace L`` with all gimbals open.

        On a dof-1 bearing every gimbal acts through the one yaw torque, so ``L`` has rank
        one and its only non-zero eigenvalue, ``trace L``, is the loop seen by a
        perturbation common to all gimbals (the loop broken at the torque command before
        the steering law). None for other loops.

        Parameters
        ----------
        discrete : bool
            The sampled loop, else the continuous design model.

        Returns
        -------
        control.StateSpace or None
        """
        if self.kind != "attitude" or self.model.dof != 1:
            return None
        L = self.loop_transfer(None, discrete=discrete)
        parts = [L[i, i] for i in range(L.ninputs)]
        out = parts[0]
        for q in parts[1:]:
            out = ct.parallel(out, q)
        return ct.ss(
            out.A, out.B, out.C, out.D, dt=L.dt, inputs=["yaw"], outputs=["yaw"], name="L_yaw"
        )

    def closed_loop(self, *, discrete: bool = True, outputs=None) -> ct.StateSpace:
        """The closed loop: inputs references and disturbances.

        Parameters
        ----------
        discrete : bool
            The sampled loop, else the continuous design model.
        outputs : sequence of str, optional
            Its outputs besides the actuator channels (default
            :meth:`default_outputs`: the true attitude error and rate states).

        Returns
        -------
        control.StateSpace
        """
        default = self.default_outputs()
        outs = list(outputs or default)
        plant, ctrl, dly = self._parts(discrete, outputs=outs)
        return ct.interconnect(
            [plant, ctrl, dly],
            inplist=list(self.references) + list(self.disturbances),
            outlist=outs + list(self.channels),
            inputs=list(self.references) + list(self.disturbances),
            outputs=outs + list(self.channels),
            check_unused=False,
            name=f"{self.name}_closed",
        )

    def default_outputs(self) -> list[str]:
        """The closed loop's default outputs: the true attitude (error) and rate states.

        Returns
        -------
        list of str
            ``true_yaw, true_wz`` (dof 1) or ``true_th_x ..`` (dof 3), and the wheel
            speeds of speed-commanded wheels.
        """
        if self.kind == "attitude":
            out = (
                ["true_yaw", "true_wz"]
                if self.model.dof == 1
                else ["true_th_x", "true_th_y", "true_th_z"]
            )
            if self.wheels and self.model.testbed.wheels.command == "speed":
                # the wheel speeds: with the commands, the torque the drivers give
                out += [f"true_W{i}" for i in range(1, self.model.testbed.wheels.n + 1)]
            return out
        return ["true_th_x", "true_th_y"]

    def stability_poles(self, *, discrete: bool = True) -> np.ndarray:
        """The closed-loop poles the loop is judged on (:meth:`stability_system`'s).

        On reaction wheels, without the poles of the wheels' stored momentum: a constant
        wheel speed is an equilibrium at any value, so each momentum direction the loop
        does not regulate is a pole at z = 1 (s = 0) whose mode moves the wheel speeds
        (and a speed command with them) and nothing else; it is neutral, not unstable
        (momentum dumping, not the attitude loop, takes it away).

        Parameters
        ----------
        discrete : bool
            z-plane poles of the sampled loop, else s-plane poles of the design model.

        Returns
        -------
        numpy.ndarray
            Complex poles.
        """
        sys = self.stability_system(discrete=discrete)
        if not self.wheels:
            return sys.poles()
        return without_momentum_poles(sys.A, body_state_mask(sys.state_labels), discrete)

    def stability_system(self, *, discrete: bool = True) -> ct.StateSpace:
        """The closed loop restricted to the states the loop acts on (for its poles).

        Parameters
        ----------
        discrete : bool
            The sampled loop, else the continuous design model.

        Returns
        -------
        control.StateSpace
            Inputs the disturbances, outputs the channels.
        """
        plant, ctrl, dly = self._parts(discrete)
        return ct.interconnect(
            [plant, ctrl, dly],
            inplist=list(self.disturbances),
            outlist=list(self.channels),
            inputs=list(self.disturbances),
            outputs=list(self.channels),
            check_unused=False,
            name=f"{self.name}_poles",
        )


def gain_dict(names, gains) -> dict:
    """A loop's gains by name, checked.

    Parameters
    ----------
    names : sequence of str
        The controller's gain names, in order.
    gains : mapping or sequence of float
        Every gain by name, or all of them in ``names`` order (SI).

    Returns
    -------
    dict
        Gain name -> float, in ``names`` order.

    Raises
    ------
    InputError
        A gain missing, unknown, not finite or negative.
    """
    if isinstance(gains, dict):
        unknown = [k for k in gains if k not in names]
        if unknown:
            raise InputError(f"gains {unknown} are not gains of this loop; expected {list(names)}")
        missing = [k for k in names if k not in gains]
        if missing:
            raise InputError(f"gains: missing {missing}; expected {list(names)}")
        out = {k: float(gains[k]) for k in names}
    else:
        vals = list(np.atleast_1d(np.asarray(gains, dtype=float)))
        if len(vals) != len(names):
            raise InputError(f"gains {vals}: expected {len(names)} values {list(names)}")
        out = dict(zip(names, map(float, vals), strict=True))
    bad = [k for k, v in out.items() if not (math.isfinite(v) and v >= 0)]
    if bad:
        raise InputError(f"gains {bad}: expected finite values >= 0, got {[out[k] for k in bad]}")
    return out
