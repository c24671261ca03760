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
linear models are their exact Jacobians about the trim
(:mod:`airbearing.design.linear_controller`). For the linearisation the balancing
actuators are ideal (no travel, speed, step or backlash limit, no dipole saturation):
these are non-smooth and checked separately against the limits.

This module builds the two loops for a testbed (:func:`make_loop`, :func:`balancing_loop`,
:func:`attitude_loop`, :func:`default_loop`); the pieces live in modules named by what they
hold: :mod:`~airbearing.design.feedback_loop` (:class:`Loop`, its python-control models,
time bases and break points), :mod:`~airbearing.design.linear_controller` (the
controller's Jacobians and trim state), :mod:`~airbearing.design.momentum_poles` (the
wheels' stored-momentum poles) and :mod:`~airbearing.design.controller_delay`
(:func:`with_delay`). Every name of :data:`__all__` is importable from here.
"""

from __future__ import annotations

import math
import os

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.attitude import SEED001_GAINS, cmg_attitude_controller
from airbearing.design.balancing import (
    MECHANICAL,
    MIXED,
    SEED000_GAINS,
    BalancingGains,
    default_split,
    pid_balancing_controller,
)
from airbearing.design.controller_delay import with_delay
from airbearing.design.feedback_loop import Loop, gain_dict
from airbearing.design.linear_controller import linear_controller
from airbearing.design.linearise import DISTURBANCE_INPUTS, linearisation, trim
from airbearing.design.momentum_poles import without_momentum_poles
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
    g = gain_dict(tuple(BALANCING_GAINS), BALANCING_GAINS if gains is None else gains)
    tp = trim(model, p)
    ideal_sliders = SliderActuator(travel=math.inf)
    kwargs = {"sliders": ideal_sliders}
    if SPLITS[split].uses_magnetorquers:
        kwargs["magnetorquers"] = MagnetorquerActuator()
    gains_ = BalancingGains.from_json(g)
    ctl = pid_balancing_controller(model, split=SPLITS[split], gains=gains_, **kwargs)
    cands = ("s1", "s2", "s3") + (("mx", "my", "mz") if split == "mixed" else ())
    channels = _active_channels(model, tp, ctl, cands)
    lc = linear_controller(model, ctl, tp, channels, "balancing")
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
        g = gain_dict(WHEEL_GAIN_NAMES, default_wheel_gains(tb) if gains is None else gains)
        opts = dict(wheel_options or {})
        wheel_kw = {k: opts[k] for k in ("bias_fraction", "bias") if k in opts}
        tp = trim(model, p, wheel_speeds=trim_wheel_speeds(tb, **wheel_kw))
        ctl = wheel_attitude_controller(model, gains=tuple(g.values()), **opts)
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
        g = gain_dict(tuple(ATTITUDE_GAINS), ATTITUDE_GAINS if gains is None else gains)
        tp = trim(model, p, gimbals=gimbals)
        ctl = cmg_attitude_controller(model, steering=steering, gains=tuple(g.values()))
        channels = _active_channels(model, tp, ctl, ("dd1", "dd2", "dd3", "dd4"))
    lc = linear_controller(model, ctl, tp, channels, "attitude")
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
