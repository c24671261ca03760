"""Standard runs: the seed-001 yaw slew, free oscillations and spin-downs of a platform."""

from __future__ import annotations

from collections.abc import Mapping
from functools import lru_cache

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.cmg.singularity import measure, pyramid_geometry
from airbearing.analysis.simulation import slew_checks as sc
from airbearing.analysis.simulation.simulate import SimResult, simulate
from airbearing.analysis.simulation.summary import free_summary, tilt_note
from airbearing.design.attitude import cmg_attitude_controller
from airbearing.design.controller import constant_input
from airbearing.design.wheels import has_wheels, wheel_attitude_controller
from airbearing.errors import InputError
from airbearing.io.coerce import as_effects, as_float, as_int, as_testbed, as_vector
from airbearing.io.testbed import Testbed
from airbearing.models.model import Model, build_model

__all__ = [
    "SCENARIO_DURATIONS", "LEVEL", "initial_attitude", "slew", "slew_loop", "slew_summary",
    "free_oscillation", "free_summary", "tilt_note", "spindown", "wheel_slew_summary",
    "SETTLE_BAND_DEG",
]  # fmt: skip

#: s, the default run length of each scenario (a seed-001 slew and its settling, a free
#: oscillation long enough for identification, a coast-down that loses most of its rate).
SCENARIO_DURATIONS = {"slew": 40.0, "free": 60.0, "spindown": 120.0}
#: The level attitude, qw qx qy qz: every scenario's default initial quaternion.
LEVEL = (1.0, 0.0, 0.0, 0.0)
#: What ``duration`` accepts, in messages.
_POSITIVE_TIME = "a positive time in s"


def _duration(duration) -> float:
    return as_float(duration, "duration", positive=True, expected=_POSITIVE_TIME)


def _quaternion(q0) -> np.ndarray:
    """``q0`` as 4 finite numbers of non-zero norm (scalar first), or an InputError."""
    what = "4 finite numbers qw qx qy qz, a non-zero quaternion (scalar first)"
    q = as_vector(q0, "q0", 4, what)
    if not np.linalg.norm(q) > 0:
        raise InputError(f"q0={tuple(q0)!r}: expected {what}")
    return q


def initial_attitude(testbed: Testbed, q0=None):
    """The initial quaternion to pass on: ``None`` (the model's own start) or ``q0``.

    A dof-1 bearing starts at yaw 0 and takes no quaternion: a level ``q0`` (the default,
    not given) becomes ``None``; any other ``q0`` is passed on for the simulation to refuse.

    Parameters
    ----------
    testbed : Testbed
    q0 : sequence of 4 float, optional
        Attitude at the start, qw qx qy qz.

    Returns
    -------
    tuple of 4 float or None
    """
    if q0 is None or (testbed.body.dof == 1 and tuple(map(float, q0)) == LEVEL):
        return None
    return tuple(q0)


def slew(
    testbed: Testbed,
    *,
    angle_deg: float = 180.0,
    axis=(0.0, 0.0, 1.0),
    duration: float = SCENARIO_DURATIONS["slew"],
    seed: int = 0,
    ideal: bool = False,
    steering: str = "mp",
    steering_options: dict | None = None,
    rate_limit_mode: str = "scale",
    form: str = "normalised",
    effects: Mapping | None = None,
    gains=None,
    loop: tuple | None = None,
    wheel_options: dict | None = None,
) -> SimResult:
    """A rest-to-rest slew of ``angle_deg`` about ``axis`` with the seed-001 attitude loop.

    On a reaction-wheel rig the same quaternion PID drives the wheels
    (:func:`~airbearing.design.wheels.wheel_attitude_controller`); the log then has the
    wheel speeds ``ws1..`` and commands ``wc1..``.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        ``kind = "cmg"`` or with ``[wheels]``, with a rate gyro (``sensors.gyro = true``);
        a built-in name or a testbed file is loaded.
    angle_deg : float
        Slew angle, deg (the loop takes the shorter way round).
    axis : sequence of 3 float
        Slew axis, body frame; a dof-1 testbed slews about z only.
    duration : float
        s (> 0), the run length at the sensor rate.
    seed : int
        Seed of the sensor and disturbance noise.
    ideal : bool
        No sensor noise, disturbance torque or gyro low-pass (the "theoretical" runs of
        seed 001 Tables 7-8).
    steering : {"mp", "sr", "gsr", "sda"}
        Steering law (:mod:`airbearing.design.steering`).
    steering_options : dict, optional
        Options of the steering law (its builder's keywords).
    rate_limit_mode : {"scale", "clip"}
        Gimbal-rate limiting: seed 001 eq. 4 scales the whole command, or clip each rate.
        On wheels: the same choice for the motor torques against ``max_torque``.
    form : str
        Jacobian form of the steering law (``"normalised"`` or ``"eq15"``).
    effects : mapping, optional
        Effects acting in the truth (FORMATS.md names and units).
    gains : dict or sequence of 3 float, optional
        Attitude gains ``{"K_p": ..., "K_i": ..., "K_w": ...}`` (as ``tune(...).gains``
        gives them) or ``(K_p, K_i, K_w)``, each >= 0; default seed 001's (wheels: N m,
        N m/s, N m s, default :func:`airbearing.design.wheels.default_wheel_gains`).
    loop : (Model, Controller), optional
        The loop to run, default :func:`slew_loop` of these arguments; a campaign passes
        one per structure with this run's values in the Model's ``p0``.
    wheel_options : dict, optional
        Wheels only: further options of the wheel controller (``attitude``,
        ``bias_gain``, ``bias_fraction``, ``bias``, ``dump_gain``, ``gyroscopic``).

    Returns
    -------
    SimResult
        The run; :func:`slew_summary` gives the numbers seed 001 reports.

    Raises
    ------
    InputError
        Not a CMG testbed, no gyro, a non-positive duration, a zero axis or one a dof-1
        bearing cannot turn about, a non-finite angle, gains that are not 3 values >= 0.

    Examples
    --------
    Seed 001 Table 8, the theoretical 90 deg slew (gimbal minimum -33.11 deg):

    >>> import airbearing as ab
    >>> run = ab.slew(ab.load_testbed("cmg-yaw"), angle_deg=90.0, duration=10.0, ideal=True)
    >>> round(ab.slew_summary(run)["gimbal_min_deg"][0], 1)
    -33.2
    """
    testbed = as_testbed(testbed)
    if testbed.kind != "cmg" and not has_wheels(testbed):
        raise InputError(
            f"{testbed.source}: the slew scenario needs a kind = 'cmg' testbed or reaction "
            f"wheels ([wheels]); '{testbed.name}' is kind = '{testbed.kind}' without wheels"
        )
    if has_wheels(testbed) and (steering != "mp" or steering_options or form != "normalised"):
        raise InputError(
            f"steering '{steering}', steering_options, form: CMG steering options; testbed "
            f"'{testbed.name}' turns on reaction wheels (allocated by the pseudo-inverse)"
        )
    duration = _duration(duration)
    angle = as_float(angle_deg, "angle_deg", "deg")
    axis = as_vector(axis, "axis", 3, "3 finite numbers, the slew axis in body axes")
    if not np.linalg.norm(axis) > 0:
        raise InputError(f"axis={tuple(axis.tolist())}: expected a non-zero slew axis")
    seed = as_int(seed, "seed")
    effects = as_effects(effects)
    if steering_options is not None and not isinstance(steering_options, Mapping):
        raise InputError(
            f"steering_options={steering_options!r:.60}: expected a dict of the steering "
            "law's options, or None"
        )
    if loop is not None and not (isinstance(loop, tuple | list) and len(loop) == 2):
        raise InputError(f"loop={loop!r:.60}: expected a (Model, Controller) pair, or None")
    if not testbed.sensors.gyro:
        raise InputError(
            f"{testbed.source}: the seed-001 attitude loop feeds back the gyro rate (eqs. 3, 19), "
            f"and testbed '{testbed.name}' has none (sensors.gyro = false)"
        )
    if wheel_options is not None and not has_wheels(testbed):
        raise InputError(f"wheel_options: testbed '{testbed.name}' has no [wheels] table")
    if loop is None and has_wheels(testbed):
        loop = slew_loop(
            testbed, effects, ideal=ideal, gains=gains, saturation=rate_limit_mode,
            **(wheel_options or {}),
        )  # fmt: skip
    elif loop is None:
        loop = slew_loop(
            testbed, effects, ideal=ideal, gains=gains, steering=steering,
            steering_options=steering_options, rate_limit_mode=rate_limit_mode, form=form,
        )  # fmt: skip
    model, ctl = loop
    if testbed.body.dof == 1 and tuple(np.round(axis, 12)) != (0.0, 0.0, 1.0):
        raise InputError("a dof = 1 testbed slews about body z only: leave the axis at 0 0 1")
    q_c = quat.from_axis_angle(axis, np.deg2rad(angle))
    return simulate(
        model, ctl, duration=duration, x0=model.x0(), reference=q_c, seed=seed, noise=not ideal
    )


def slew_loop(
    testbed: Testbed, effects: Mapping | None = None, *, ideal: bool = False, gains=None, **steering
) -> tuple[Model, object]:
    """The Model and seed-001 attitude controller a :func:`slew` runs.

    ``effects``, ``ideal`` and ``gains`` as in :func:`slew`; ``steering``: the controller's
    ``steering``, ``steering_options``, ``rate_limit_mode`` and ``form``
    (:func:`airbearing.design.attitude.cmg_attitude_controller`), or on a reaction-wheel
    rig the wheel controller's options
    (:func:`airbearing.design.wheels.wheel_attitude_controller`).

    Returns
    -------
    (Model, Controller)
    """
    model = build_model(as_testbed(testbed), as_effects(effects))
    kwargs = {} if gains is None else {"gains": gains}
    if has_wheels(model.testbed):  # steering: the wheel controller's options
        ctl = wheel_attitude_controller(model, lowpass=1.0 if ideal else None, **steering, **kwargs)
        return model, ctl
    ctl = cmg_attitude_controller(model, lowpass=1.0 if ideal else None, **steering, **kwargs)
    return model, ctl


def slew_summary(result: SimResult) -> dict:
    """The numbers seed 001 reports for a slew (Tables 7-8), in degrees.

    Parameters
    ----------
    result : SimResult
        A run of :func:`slew`.

    Returns
    -------
    dict
        ``peak_rate_deg_s`` and ``t_peak_s`` (s), ``gimbal_min_deg``, ``gimbal_max_deg``,
        ``gimbal_final_deg`` (4 each), ``final_yaw_error_deg``, ``final_yaw_deg``,
        ``duration_s`` (s): the ``airbearing simulate --scenario slew --json`` keys; and
        what the slew ran into (:mod:`~airbearing.analysis.simulation.slew_checks`):
        ``momentum_capacity_nms`` (N m s, the most the cluster stores along the slew
        axis), ``momentum_peak_fraction`` (-, the largest share of it the run used),
        ``saturation`` (episodes ``{"start_s", "end_s"}`` when the cluster was at that
        envelope while the loop asked for more), ``gimbal_rate_chatter`` (episodes
        ``{"start_s", "end_s", "samples", "reversal_samples"}`` when the gimbal-rate
        command reversed sign sample after sample) and ``warnings`` (both in words).

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.slew(ab.load_testbed("cmg-yaw"), angle_deg=30.0, duration=5.0, ideal=True)
    >>> summary = ab.slew_summary(run)
    >>> round(summary["peak_rate_deg_s"], 1), round(summary["final_yaw_deg"], 1)  # deg/s, deg
    (11.1, 29.1)
    >>> summary["warnings"]
    []
    """
    m = result.model
    if has_wheels(m.testbed):
        return wheel_slew_summary(result)
    w_idx = m.index(["wx", "wy", "wz"] if m.dof == 3 else ["wz"])
    w = result.x[:, w_idx]
    rate = np.linalg.norm(w, axis=1)
    k = int(np.argmax(rate))
    d = result.x[:, m.index(["d1", "d2", "d3", "d4"])]
    t = np.append(result.t, result.t[-1] + m.testbed.sensors.dt)
    q_end = result.x[-1, 0:4] if m.dof == 3 else quat.from_yaw(result.x[-1, 0])
    err = quat.qmul(quat.qconj(quat.normalize(result.reference[-1, :4])), q_end)
    final_err = float(np.rad2deg(2 * np.arccos(min(1.0, abs(err[0])))))
    return {
        "peak_rate_deg_s": float(np.rad2deg(rate[k])),
        "t_peak_s": float(t[k]),
        "gimbal_min_deg": np.rad2deg(d.min(axis=0)).tolist(),
        "gimbal_max_deg": np.rad2deg(d.max(axis=0)).tolist(),
        "gimbal_final_deg": np.rad2deg(d[-1]).tolist(),
        "final_yaw_error_deg": final_err,
        "final_yaw_deg": float(np.rad2deg(quat.yaw_of(q_end))),
        "duration_s": float(t[-1]),
        **_saturation_and_chatter(result, d),
    }


#: deg, the settling band of a slew: seed 001 Table 6's a_err.
SETTLE_BAND_DEG = 1.5


def wheel_slew_summary(result: SimResult) -> dict:
    """A reaction-wheel slew's numbers: the attitude ones of :func:`slew_summary` and the
    wheels'.

    Parameters
    ----------
    result : SimResult
        A :func:`slew` of a testbed with ``[wheels]``.

    Returns
    -------
    dict
        ``peak_rate_deg_s``, ``t_peak_s`` (s), ``final_yaw_error_deg``, ``final_yaw_deg``,
        ``settling_time_s`` (s: from the start until the attitude error stays within
        :data:`SETTLE_BAND_DEG`; None when it never does), ``duration_s`` (s);
        ``wheel_speed_min_rad_s``, ``wheel_speed_max_rad_s``, ``wheel_speed_final_rad_s``
        (rad/s, one per wheel), ``wheel_momentum_peak_nms`` (N m s, the largest ``|A^T Iw
        W|``), ``torque_saturated_s`` (s the wheels spent at ``max_torque`` while the
        loop asked for more) and ``warnings``.
    """
    m = result.model
    wh = m.testbed.wheels
    w = result.x[:, m.index(["wx", "wy", "wz"] if m.dof == 3 else ["wz"])]
    rate = np.linalg.norm(w, axis=1)
    k = int(np.argmax(rate))
    dt = m.testbed.sensors.dt
    t = np.append(result.t, result.t[-1] + dt)
    q = result.x[:, 0:4] if m.dof == 3 else quat.from_yaw(result.x[:, 0])
    q_ref = quat.normalize(np.vstack([result.reference[:, :4], result.reference[-1:, :4]]))
    err = quat.qmul(quat.qconj(q_ref), q)
    err_deg = np.rad2deg(2 * np.arccos(np.minimum(1.0, np.abs(err[:, 0]))))
    out_of_band = np.nonzero(err_deg > SETTLE_BAND_DEG)[0]
    if out_of_band.size == 0:
        settling = 0.0
    elif out_of_band[-1] == len(err_deg) - 1:
        settling = None
    else:
        settling = float(t[out_of_band[-1] + 1])
    W = result.x[:, m.index([f"W{i}" for i in range(1, wh.n + 1)])]
    h = (W * np.asarray(wh.inertia_vec, float)) @ np.asarray(wh.axes_matrix, float)
    names = list(result.controller.extra_names)
    sat_s = 0.0
    if "wsat" in names:
        sat_s = float(np.count_nonzero(result.extra[:, names.index("wsat")] > 1.0) * dt)
    warnings = []
    if sat_s > 0:
        warnings.append(
            f"the wheels were at max_torque = {wh.max_torque:g} N m for {sat_s:.2f} s while "
            "the loop asked for more: the slew was torque-limited"
        )
    top = float(np.abs(W).max())
    if top >= 0.99 * wh.max_speed:
        warnings.append(
            f"a wheel reached {top:.4g} rad/s, its max_speed {wh.max_speed:g}: the wheels "
            "saturated in momentum and could not give the torque asked for"
        )
    return {
        "peak_rate_deg_s": float(np.rad2deg(rate[k])),
        "t_peak_s": float(t[k]),
        "final_yaw_error_deg": float(err_deg[-1]),
        "final_yaw_deg": float(np.rad2deg(quat.yaw_of(q[-1]))),
        "settling_time_s": settling,
        "duration_s": float(t[-1]),
        "wheel_speed_min_rad_s": W.min(axis=0).tolist(),
        "wheel_speed_max_rad_s": W.max(axis=0).tolist(),
        "wheel_speed_final_rad_s": W[-1].tolist(),
        "wheel_momentum_peak_nms": float(np.linalg.norm(h, axis=1).max()),
        "torque_saturated_s": sat_s,
        "warnings": warnings,
    }


def _saturation_and_chatter(result: SimResult, d: np.ndarray) -> dict:
    """The envelope and chatter keys of :func:`slew_summary` (``d``: true gimbal angles,
    rad, at ``t_0 .. t_N``)."""
    m = result.model
    cmg = m.testbed.cmg
    u = np.array([0.0, 0.0, 1.0])
    if m.dof == 3:  # the slew axis: the reference rotation's, fixed in body axes
        v = np.asarray(result.reference[-1, 1:4], float)
        u = v / np.linalg.norm(v) if np.linalg.norm(v) > 1e-12 else u
    cap = sc.envelope_capacity(cmg.skew, u)
    H = pyramid_geometry(cmg.skew).momentum_vectors(d[:-1]).sum(axis=-2)  # seed 001 eq. 12
    names = list(result.controller.extra_names)
    torque = result.extra[:, [names.index(f"Tc_{a}") for a in "xyz"]]
    peak, saturation = sc.saturation_episodes(result.t, H, torque, u, cap)
    dd = result.u[:, m.index(["dd1", "dd2", "dd3", "dd4"], "u")]
    chatter = sc.chatter_episodes(result.t, dd, cmg.max_gimbal_rate)
    J = np.asarray(m.testbed.body.inertia_matrix, float)
    cap_nms = cap * cmg.h0
    warnings = sc.slew_warnings(
        saturation, chatter, capacity_nms=cap_nms, capacity_h0=cap,
        rate_cap_deg_s=float(np.rad2deg(cap_nms / (u @ J @ u))),
        gimbals_deg=(result.t, np.rad2deg(d[:-1])), measure=measure(d[:-1], cmg.skew),
    )  # fmt: skip
    return {
        "momentum_capacity_nms": cap_nms,
        "momentum_peak_fraction": peak,
        "saturation": saturation,
        "gimbal_rate_chatter": chatter,
        "warnings": warnings,
    }


def free_oscillation(
    testbed: Testbed,
    *,
    initial_rate=(0.0, 0.0, 0.0),
    q0=(1.0, 0.0, 0.0, 0.0),
    sliders=(0.0, 0.0, 0.0),
    effects: Mapping | None = None,
    duration: float = SCENARIO_DURATIONS["free"],
    seed: int = 0,
    noise: bool = True,
    attitude_noise: float | None = None,
    model: Model | None = None,
    substeps: int | None = None,
) -> SimResult:
    """Free motion with inputs held: sliders at ``sliders`` (m), no dipole, the cage field on.

    The data that identification and the discrepancy workflow consume. ``effects``
    (FORMATS.md names and units) act in the truth but are not written to any testbed.
    Works on passive platforms (no ``[masses]``: ``sliders`` must stay zero) and on
    dof-1 bearings (only the z entry of ``initial_rate`` may be non-zero). The log
    follows the testbed's sensors: ``sensors.gyro = false`` gives attitude only, with
    ``attitude_noise`` (default ``sensors.attitude_noise``, rad).

    Parameters
    ----------
    testbed : Testbed, str or path-like
        The testbed, a built-in name or a testbed file.
    initial_rate : sequence of 3 float
        Body rates at the start, rad/s.
    q0 : sequence of 4 float
        Attitude at the start (scalar first).
    sliders : sequence of 3 float
        Slider positions held during the run, m (platforms with ``[masses]``).
    effects : mapping, optional
        Effects acting in the truth (FORMATS.md names and units).
    duration : float
        s (> 0).
    seed : int
        Seed of the measurement noise.
    noise : bool
        Measurement noise on (default) or off.
    attitude_noise : float, optional
        rad, 1-sigma attitude noise of an attitude-only log.
    model : Model, optional
        The Model to run, default ``build_model(testbed, effects)``; a campaign passes one
        Model per structure with this run's values in ``p0``, and reuses its compiled loop.
    substeps : int, optional
        RK4 sub-steps per sample (default: as many as the truth needs, :func:`simulate`).

    Returns
    -------
    SimResult

    Raises
    ------
    InputError
        A non-positive duration, sliders on a testbed without ``[masses]`` or beyond their
        travel, a rate a dof-1 bearing cannot have.

    Examples
    --------
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("seed004-platform")
    >>> run = ab.free_oscillation(tb, initial_rate=(0.3, -0.2, 0.5), duration=5.0)
    >>> run.to_json()["samples"], list(run.log.data.columns[:5])
    (100, ['t', 'qw', 'qx', 'qy', 'qz'])
    >>> ab.free_oscillation(tb, duration=-1.0)
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: duration=-1.0: expected a positive time in s
    """
    testbed = as_testbed(testbed)
    duration = _duration(duration)
    seed = as_int(seed, "seed")
    q0 = tuple(_quaternion(q0).tolist())
    effects = as_effects(effects)
    if model is not None and not isinstance(model, Model):
        raise InputError(f"model={model!r:.60}: expected a Model (build_model(testbed)), or None")
    model = build_model(testbed, effects) if model is None else model
    u = _free_inputs(testbed, model, sliders)
    w0 = _initial_rate(model, initial_rate, q0)
    x0 = model.x0(q=q0, w=w0) if model.dof == 3 else model.x0(w=w0[2])
    return simulate(
        model,
        _held_input(model, tuple(u.tolist())),
        duration=duration,
        x0=x0,
        seed=seed,
        noise=noise,
        attitude_noise=attitude_noise,
        substeps=substeps,
    )


def _free_inputs(testbed: Testbed, model: Model, sliders) -> np.ndarray:
    """The held input of a free oscillation: sliders at ``sliders`` (m), the cage field on."""
    u = np.zeros(model.nu)
    if testbed.kind == "platform":
        s = as_vector(sliders, "sliders", 3, "3 finite slider positions in m")
        if testbed.masses is None and np.any(s != 0):
            raise InputError(
                f"sliders={s.tolist()}: testbed '{testbed.name}' has no [masses] table "
                "(a passive platform); leave the sliders at 0"
            )
        travel = testbed.masses.travel if testbed.masses else 0.0
        if np.any(np.abs(s) > travel):
            raise InputError(
                f"sliders={s.tolist()}: each must lie within +-{travel} m (masses.travel)"
            )
        u[model.index(["s1", "s2", "s3"], "u")] = s
        if testbed.field is not None:
            u[model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = testbed.field.lab_vec
    elif np.any(as_vector(sliders, "sliders", 3, "3 finite slider positions in m") != 0):
        raise InputError("sliders applies to kind = 'platform' testbeds only")
    return u


def _initial_rate(model: Model, initial_rate, q0) -> np.ndarray:
    """``initial_rate`` (rad/s) checked against the bearing (dof 1: about z, from yaw 0)."""
    w0 = as_vector(initial_rate, "initial_rate", 3, "3 finite rates wx wy wz in rad/s")
    if model.dof == 1 and np.any(w0[:2] != 0):
        raise InputError(
            f"initial_rate={w0.tolist()}: a dof = 1 bearing turns about body z only; "
            "give WX = WY = 0"
        )
    if model.dof == 1 and tuple(np.asarray(q0, dtype=float)) != (1.0, 0.0, 0.0, 0.0):
        raise InputError(
            f"q0={list(map(float, q0))}: a dof = 1 bearing starts at yaw 0; "
            "leave the quaternion at 1 0 0 0"
        )
    return w0


@lru_cache(maxsize=16)
def _held_input(model: Model, u: tuple):
    """``constant_input(model, u)``, the same object for the same Model and ``u``: a Model
    reused across runs (a campaign's) then reuses its compiled loop too."""
    return constant_input(model, np.array(u))


def spindown(
    testbed: Testbed,
    *,
    initial_rate: float = 2.0,
    duration: float = SCENARIO_DURATIONS["spindown"],
    effects: Mapping | None = None,
    seed: int = 0,
    noise: bool = True,
    q0=(1.0, 0.0, 0.0, 0.0),
    attitude_noise: float | None = None,
) -> SimResult:
    """A spin-down: the platform spun about body z at ``initial_rate`` (rad/s), coasting.

    Nothing but its effects (friction, drag, ...) and, on a dof-3 bearing, gravity of the
    CM offset act; sliders at zero, no dipole. The log follows the testbed's sensors
    (attitude only when ``sensors.gyro = false``). A thin form of
    :func:`free_oscillation` with ``initial_rate = (0, 0, initial_rate)``.

    Parameters
    ----------
    testbed : Testbed, str or path-like
        The testbed, a built-in name or a testbed file.
    initial_rate : float
        rad/s about body z at the start.
    duration : float
        s (> 0).
    effects : mapping, optional
        Effects acting in the truth (FORMATS.md names and units), e.g. friction.
    seed : int
        Seed of the measurement noise.
    noise : bool
        Measurement noise on (default) or off.
    q0 : sequence of 4 float
        Attitude at the start (scalar first).
    attitude_noise : float, optional
        rad, 1-sigma attitude noise of an attitude-only log.

    Returns
    -------
    SimResult

    Examples
    --------
    A viscous coast-down: ``J w' = -c w``, so the rate decays as ``exp(-c t / J)``.

    >>> import math
    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> run = ab.spindown(tb, initial_rate=1.0, duration=10.0, noise=False,
    ...                   effects={"viscous_friction": 1e-4})
    >>> J = tb.body.inertia_matrix[2][2]
    >>> w_end = run.state("wz")[-1]
    >>> bool(abs(w_end / math.exp(-1e-4 * run.t[-1] / J) - 1) < 1e-9)  # RK4 at 20 Hz
    True
    """
    w = as_float(
        initial_rate, "initial_rate", expected="a finite rate in rad/s about body z (one number)"
    )
    return free_oscillation(
        testbed,
        initial_rate=(0.0, 0.0, w),
        q0=q0,
        effects=effects,
        duration=duration,
        seed=seed,
        noise=noise,
        attitude_noise=attitude_noise,
    )
