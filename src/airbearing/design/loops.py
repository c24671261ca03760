"""The two feedback loops of the package as python-control interconnections.

* **Balancing loop** (seeds 000 and 004): the platform linearised about the balanced
  point (a pendulum: torque ``mass g r_z`` per radian of tilt), the in-plane PID of seed
  000 eq. 3 as implemented by :func:`airbearing.design.balancing.pid_balancing_controller`
  with its split between sliders and magnetorquers (``mechanical``: seed 000 eq. 8, all
  terms through the sliders; ``mixed``: eqs. 5 and 7, P and I through the sliders, D
  through the magnetorquers).
* **Attitude loop** (seed 001): the CMG testbed linearised at a gimbal set, the
  quaternion PID of seed 001 eq. 19 with the gyro low-pass (eq. 3), the attitude
  propagation (eq. 21) and the steering law (eq. 16), as implemented by
  :func:`airbearing.design.attitude.cmg_attitude_controller`; on a reaction-wheel rig
  the same quaternion PID drives the wheels
  (:func:`airbearing.design.wheels.wheel_attitude_controller`), the loop broken at each
  wheel's command, the wheels trimmed at the speeds the loop holds.

The controllers are the very CasADi Functions the nonlinear simulation runs: their
linear models are their exact Jacobians (``ca.jacobian``) about the trim, with the gains
as an input of the Jacobian Function (built once, evaluated for any gains). For the
linearisation the balancing actuators are ideal (no travel, speed, step or backlash
limit, no dipole saturation): these are non-smooth and checked separately against the
limits.

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
import os
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design import _control as ct
from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.attitude import PID_STATES, SEED001_GAINS, cmg_attitude_controller
from airbearing.design.balancing import (
    MECHANICAL,
    MIXED,
    SEED000_GAINS,
    BalancingGains,
    default_split,
    pid_balancing_controller,
)
from airbearing.design.controller import Controller
from airbearing.design.linearise import (
    DISTURBANCE_INPUTS,
    TrimPoint,
    d2c_bilinear,
    delay_system,
    linearisation,
    prune_states,
    trim,
)
from airbearing.design.wheels import (
    WHEEL_GAIN_NAMES,
    default_wheel_gains,
    has_wheels,
    trim_wheel_speeds,
    wheel_attitude_controller,
)
from airbearing.errors import InputError
from airbearing.io.coerce import as_testbed
from airbearing.io.testbed import Testbed
from airbearing.models.model import Model
from airbearing.models.structure_cache import built_model

__all__ = [
    "Loop",
    "LOOPS",
    "SPLITS",
    "BALANCING_GAINS",
    "ATTITUDE_GAINS",
    "balancing_loop",
    "attitude_loop",
    "make_loop",
    "default_loop",
    "with_delay",
    "without_momentum_poles",
]

#: Loop kinds the package builds.
LOOPS = ("balancing", "attitude")
#: PID splits of the balancing loop (seed 000 eq. 8 and eqs. 5, 7).
SPLITS = {"mechanical": MECHANICAL, "mixed": MIXED}
#: Gain names and seed values: seed 000 Tables 1-2 (K_p N m, K_d N m s, K_d K_i N m/s).
BALANCING_GAINS = SEED000_GAINS.to_json()
#: Seed 001 Table 6 (normalised form: torque = h0 times the command).
ATTITUDE_GAINS = dict(zip(("K_p", "K_i", "K_w"), SEED001_GAINS, strict=True))
_TRIM_TOL = 1e-9  # relative residual accepted for the controller's trim state


@dataclass(frozen=True, eq=False)
class _LinearController:
    """Jacobians of a discrete Controller about its trim, with the gains as an input."""

    fn: ca.Function  # (gains, c_trim) -> (A, B, C, D): x = c, inputs [y_used; ref], outputs u_ch
    trim_fn: ca.Function  # gains -> (residual Jacobian, residual) to solve for c_trim
    n_c: int
    c0: np.ndarray  # the controller's initial state: the start of the trim solve
    inputs: tuple  # measurement names used, then reference names
    outputs: tuple  # channel names


@dataclass(frozen=True, eq=False)
class Loop:
    """One feedback loop: plant, controller, trim, gains and the python-control models.

    Build with :func:`balancing_loop` or :func:`attitude_loop`. A Loop is immutable;
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
    _lin_ctrl: _LinearController = field(repr=False)
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
        return replace(self, gains=_gain_dict(self.controller.gain_names, gains))

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
        return _controller_trim(self._lin_ctrl, self.gain_vector)

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
        return without_momentum_poles(sys.A, _body_state_mask(sys.state_labels), discrete)

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


#: |z - 1| (or |s| times the sample time) within which a pole is the wheels' momentum,
#: and the largest share of its mode on the body and PID states.
_MOMENTUM_TOL = 1e-8
_MOMENTUM_SHARE = 1e-6


def _body_state_mask(labels) -> np.ndarray:
    """True for the states of an interconnected wheel loop that a stored-momentum mode
    leaves at rest: the body's (not ``W<i>``) and the PID's (controller states ``c0..c9``,
    :data:`~airbearing.design.attitude.PID_STATES`); the delay's and the speed targets'
    states may move with the wheels."""
    out = []
    for lbl in labels:
        name = lbl.split("_", 1)[1] if "_" in lbl else lbl
        if lbl.startswith("plant_"):
            out.append(not (name.startswith("W") and name[1:].isdigit()))
        elif lbl.startswith("controller_c") and name[1:].isdigit():
            out.append(int(name[1:]) < PID_STATES)
        else:
            out.append(False)
    return np.array(out, dtype=bool)


def without_momentum_poles(A, body_mask, discrete: bool = True, dt: float = 1.0) -> np.ndarray:
    """The eigenvalues of the closed-loop ``A`` without those of stored wheel momentum:
    at z = 1 (s = 0) within :data:`_MOMENTUM_TOL`, with a mode that leaves the states of
    ``body_mask`` at rest (share below :data:`_MOMENTUM_SHARE`)."""
    A = np.asarray(A, dtype=float)
    if A.size == 0:
        return np.zeros(0, complex)
    lam, V = np.linalg.eig(A)
    at = np.abs(lam - 1) if discrete else np.abs(lam) * dt
    keep = np.ones(lam.size, dtype=bool)
    for i in np.nonzero(at < _MOMENTUM_TOL)[0]:
        v = np.abs(V[:, i])
        if v[body_mask].max(initial=0.0) <= _MOMENTUM_SHARE * v.max():
            keep[i] = False
    return lam[keep]


def _gain_dict(names, gains) -> dict:
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


# ---------------------------------------------------------------------- helpers


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


# ---------------------------------------------------------------------- controller Jacobians


def _linear_controller(
    model: Model, controller: Controller, trim_point: TrimPoint, channels, ref_expr, ref_names
) -> _LinearController:
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
    return _LinearController(
        fn,
        trim_fn,
        nc,
        np.asarray(controller.c0, float),
        tuple(model.y_names[i] for i in used) + tuple(ref_names),
        tuple(channels),
    )


def _controller_trim(lc: _LinearController, gains: np.ndarray, c0=None) -> np.ndarray:
    """Controller state holding the trim: ``c_next = c`` and ``u = u_trim`` (Newton, exact)."""
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
        raise InputError(
            "the controller cannot hold the trim with these gains (residual "
            f"{np.abs(r).max():.3g}): the balancing loop needs integral action (K_dK_i > 0)"
        )
    return c


# ---------------------------------------------------------------------- builders


def _as_model(testbed_or_model) -> Model:
    if isinstance(testbed_or_model, Model):
        return testbed_or_model
    if isinstance(testbed_or_model, Testbed):
        return _model_of(testbed_or_model)
    if isinstance(testbed_or_model, str | os.PathLike):  # a built-in name or a testbed file
        return _model_of(as_testbed(testbed_or_model))
    raise InputError(
        f"testbed={testbed_or_model!r}: expected a Testbed, a Model, a built-in testbed name "
        "or a testbed file path"
    )


def _model_of(testbed: Testbed) -> Model:
    return built_model(testbed)


def _active_channels(model, trim_point, controller, candidates) -> tuple:
    """Channels that both move the plant and are driven by the controller."""
    A, B, C, D = linearisation(model).matrices(trim_point)
    y_star = np.asarray(model.h(trim_point.x, trim_point.u, trim_point.p)).ravel()
    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", controller.c0.size)
    u, _, _ = controller.function(
        y, c, ca.DM(controller_ref0(model, controller)), controller.gains, 0.0
    )
    Jy = ca.Function("jy", [y, c], [ca.jacobian(u, y)])(y_star, controller.c0)
    Jy = np.asarray(Jy)
    out = []
    for name in candidates:
        i = model.index(name, "u")[0]
        if np.any(B[:, i] != 0) and np.any(Jy[i] != 0):
            out.append(name)
    return tuple(out)


def controller_ref0(model, controller) -> np.ndarray:
    return np.zeros(len(controller.ref_names)) if not controller.ref_names else quat.from_yaw(0.0)


def balancing_loop(
    testbed_or_model,
    *,
    split: str | None = None,
    gains=None,
    p=None,
    delay_samples: int = 1,
) -> Loop:
    """The balancing loop of seeds 000/004 about the balanced platform.

    Parameters
    ----------
    testbed_or_model : Testbed or Model
        A ``kind = "platform"``, dof 3 testbed.
    split : {"mixed", "mechanical"}, optional
        Which actuator carries which PID term (seed 000 eqs. 5, 7 / eq. 8); default the
        split the testbed can run (:func:`~airbearing.design.balancing.default_split`).
    gains : mapping or sequence, optional
        ``K_p`` (N m), ``K_d`` (N m s), ``K_dK_i`` (N m/s); default seed 000 Tables 1-2.
    p : ndarray, optional
        Plant parameters (default the nominal ones).
    delay_samples : int
        Computation delay of the discrete loop, samples (default 1).
    """
    model = _as_model(testbed_or_model)
    tb = model.testbed
    if model.kind != "platform" or model.dof != 3:
        raise InputError(
            f"{tb.source}: the balancing loop needs a kind = 'platform', dof = 3 testbed; "
            f"'{tb.name}' is kind = '{model.kind}', dof = {model.dof}"
        )
    split = default_split(tb) if split is None else split
    if split not in SPLITS:
        raise InputError(f"split '{split}': expected one of {', '.join(SPLITS)}")
    g = _gain_dict(tuple(BALANCING_GAINS), BALANCING_GAINS if gains is None else gains)
    tp = trim(model, p)
    ideal_sliders = SliderActuator(travel=math.inf)
    kwargs = {"sliders": ideal_sliders}
    if SPLITS[split].uses_magnetorquers:
        kwargs["magnetorquers"] = MagnetorquerActuator()
    gains_ = BalancingGains.from_json(g)
    ctl = pid_balancing_controller(model, split=SPLITS[split], gains=gains_, **kwargs)
    cands = ("s1", "s2", "s3") + (("mx", "my", "mz") if split == "mixed" else ())
    channels = _active_channels(model, tp, ctl, cands)
    lc = _lin_ctrl_cached(model, ctl, tp, channels, "balancing")
    notes = tuple(f"trim: {v}" for v in tp.limit_violations)
    return Loop(
        kind="balancing",
        name=f"balancing-{split}",
        model=model,
        trim=tp,
        controller=ctl,
        gains=g,
        channels=channels,
        references=(),
        disturbances=("tau_x", "tau_y"),
        p=tp.p,
        delay_samples=delay_samples,
        _lin_ctrl=lc,
        notes=notes,
    )


def attitude_loop(
    testbed_or_model,
    *,
    gains=None,
    p=None,
    gimbals=None,
    steering: str = "mp",
    delay_samples: int = 1,
    wheel_options: dict | None = None,
) -> Loop:
    """The attitude loop: seed 001's on a CMG testbed at a gimbal set, or the same
    quaternion PID on reaction wheels (:mod:`airbearing.design.wheels`).

    Parameters
    ----------
    testbed_or_model : Testbed or Model
        A ``kind = "cmg"`` testbed (dof 1 or 3), or a testbed with ``[wheels]``.
    gains : mapping or sequence, optional
        ``K_p, K_i, K_w``: CMG in the normalised form (torque = h0 times the command),
        default seed 001 Table 6 (6, 0.001, 6); wheels in N m, N m/s, N m s, default
        :func:`~airbearing.design.wheels.default_wheel_gains`.
    p : ndarray, optional
        Plant parameters.
    gimbals : (4,) rad, optional
        Gimbal set of the trim (default the testbed's).
    steering : str
        Steering law (:data:`airbearing.design.steering.STEERING_LAWS`).
    delay_samples : int
        Computation delay of the discrete loop, samples.
    wheel_options : dict, optional
        Wheels only: options of
        :func:`~airbearing.design.wheels.wheel_attitude_controller` (``attitude``,
        ``lowpass``, ``saturation``, ``bias_gain``, ``bias_fraction``, ``bias``,
        ``dump_gain``, ``gyroscopic``). The wheels are trimmed at the speeds the loop
        holds (the testbed's, with the null-space part at the bias).
    """
    model = _as_model(testbed_or_model)
    tb = model.testbed
    if has_wheels(tb):
        if gimbals is not None or steering != "mp":
            raise InputError(
                f"gimbals, steering: CMG options; testbed '{tb.name}' turns on reaction wheels"
            )
        g = _gain_dict(WHEEL_GAIN_NAMES, default_wheel_gains(tb) if gains is None else gains)
        opts = dict(wheel_options or {})
        wheel_kw = {k: opts[k] for k in ("bias_fraction", "bias") if k in opts}
        tp = trim(model, p, wheel_speeds=trim_wheel_speeds(tb, **wheel_kw))
        ctl = wheel_attitude_controller(model, gains=tuple(g.values()), **opts)
        if opts:  # the Jacobian cache is keyed by the controller's name
            ctl = replace(ctl, name=f"{ctl.name}{sorted(opts.items())!r}")
        cands = tuple(f"wc{i}" for i in range(1, tb.wheels.n + 1))
        channels = _active_channels(model, tp, ctl, cands)
    else:
        if model.kind != "cmg":
            raise InputError(
                f"{tb.source}: the attitude loop needs a kind = 'cmg' testbed or a [wheels] "
                f"table; '{tb.name}' is kind = '{model.kind}' without wheels"
            )
        if wheel_options:
            raise InputError(f"wheel_options: testbed '{tb.name}' has no [wheels] table")
        g = _gain_dict(tuple(ATTITUDE_GAINS), ATTITUDE_GAINS if gains is None else gains)
        tp = trim(model, p, gimbals=gimbals)
        ctl = cmg_attitude_controller(model, steering=steering, gains=tuple(g.values()))
        channels = _active_channels(model, tp, ctl, ("dd1", "dd2", "dd3", "dd4"))
    lc = _lin_ctrl_cached(model, ctl, tp, channels, "attitude")
    refs = ("yaw_ref",) if model.dof == 1 else ("ref_x", "ref_y", "ref_z")
    dist = ("tau_z",) if model.dof == 1 else DISTURBANCE_INPUTS
    return Loop(
        kind="attitude",
        name="attitude",
        model=model,
        trim=tp,
        controller=ctl,
        gains=g,
        channels=channels,
        references=refs,
        disturbances=dist,
        p=tp.p,
        delay_samples=delay_samples,
        _lin_ctrl=lc,
    )


_LC_CACHE: dict = {}


def _lin_ctrl_cached(model, ctl, tp, channels, kind) -> _LinearController:
    key = (
        id(model),
        kind,
        ctl.name,
        tuple(channels),
        tuple(np.round(tp.x, 12)),
        tuple(np.round(tp.u, 12)),
    )
    hit = _LC_CACHE.get(key)
    if hit is not None and hit[0] is model:
        return hit[1]
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

    lc = _linear_controller(model, ctl, tp, channels, ref_expr, names)
    if len(_LC_CACHE) > 32:
        _LC_CACHE.clear()
    _LC_CACHE[key] = (model, lc)
    return lc


def default_loop(testbed) -> str:
    """The loop a testbed has: the attitude loop of a CMG or reaction-wheel testbed, a
    platform's balancing loop.

    Parameters
    ----------
    testbed : Testbed or Model

    Returns
    -------
    str
        ``"attitude"`` or ``"balancing"`` (:data:`LOOPS`).

    Examples
    --------
    >>> import airbearing as ab
    >>> default_loop(ab.load_testbed("cmg-yaw")), default_loop(ab.load_testbed("rw-yaw"))
    ('attitude', 'attitude')
    """
    tb = getattr(testbed, "testbed", testbed)
    return "attitude" if tb.kind == "cmg" or tb.wheels is not None else "balancing"


def make_loop(testbed_or_model, loop: str, **options) -> Loop:
    """:func:`balancing_loop` or :func:`attitude_loop` by name.

    Parameters
    ----------
    testbed_or_model : Testbed or Model
    loop : {"balancing", "attitude"}
        The balancing loop of a platform with sliders, or the attitude loop of a CMG
        testbed or of a reaction-wheel rig.
    **options
        Passed on: ``gains`` (dict, SI; default the seed's), ``split`` (balancing).

    Returns
    -------
    Loop

    Raises
    ------
    InputError
        An unknown loop name, or a loop the testbed does not have.

    Examples
    --------
    >>> import airbearing as ab
    >>> ab.make_loop(ab.load_testbed("cmg-yaw"), "pitch")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: loop='pitch': expected one of balancing|attitude
    """
    if loop == "balancing":
        return balancing_loop(testbed_or_model, **options)
    if loop == "attitude":
        return attitude_loop(testbed_or_model, **options)
    raise InputError(f"loop={loop!r}: expected one of {'|'.join(LOOPS)}")
