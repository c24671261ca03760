"""The CMG attitude loop of seed 001: gyro filter, attitude propagation, PID, steering."""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.controller import Controller
from airbearing.design.steering import saturate_rates, steering_function
from airbearing.errors import InputError
from airbearing.io.coerce import as_gains
from airbearing.models.cmg import jacobian_normalised, momentum_normalised

__all__ = ["cmg_attitude_controller", "SEED001_GAINS", "quaternion_pid", "pid_c0", "PID_STATES"]

#: K_p, K_i, K_w of seed 001 Table 6 (normalised form: torque per h0).
SEED001_GAINS = (6.0, 0.001, 6.0)
#: The gains' names, in order.
GAIN_NAMES = ("K_p", "K_i", "K_w")
#: What the controller logs each sample: attitude estimate, filtered rate, commanded torque,
#: the estimate's yaw.
EXTRA_NAMES = ("qe_w", "qe_x", "qe_y", "qe_z", "G_x", "G_y", "G_z", "Tc_x", "Tc_y", "Tc_z",
               "yaw_est")  # fmt: skip


def cmg_attitude_controller(
    model,
    *,
    steering: str = "mp",
    steering_options: dict | None = None,
    form: str = "normalised",
    rate_limit_mode: str = "scale",
    lowpass: float | None = None,
    attitude: str = "gyro",
    encoder_resolution: float = 0.0,
    gains=SEED001_GAINS,
) -> Controller:
    """Seed 001's attitude controller as a discrete CasADi block.

    Each sample: the gyro is low-pass filtered (seed 001 eq. 3); the attitude
    estimate is propagated with the previous filtered rate (seed 001 eq. 21) or taken
    from the measurement (``attitude="measured"``, dof 3 only); the error quaternion
    ``q_err = q_c* (x) q`` (eq. 20) feeds the PID ``T_c = -(Kp q_v + Ki int q_v dt + Kw w)``
    (eq. 19); the wanted momentum rate ``h_dot = -T_c - w x h`` (eq. 11) is turned into
    gimbal rates by the steering law (eq. 16) and rate-limited (eq. 4).

    Parameters
    ----------
    model : Model
        A ``kind = "cmg"`` Model.
    steering : str
        Steering-law name (:data:`airbearing.design.steering.STEERING_LAWS`).
    form : {"normalised", "physical"}
        ``"normalised"`` steers with ``A`` without ``h0`` as seed 001 does, so the gains
        are torques per unit ``h0``; ``"physical"`` uses ``h0 A`` and gains in N m.
    rate_limit_mode : {"scale", "clip"}
        Seed 001 eq. 4 (scale all four) or per-gimbal clipping.
    lowpass : float, optional
        Smoothing factor ``f_g`` of eq. 3; default the testbed's ``sensors.lowpass``.
    attitude : {"gyro", "measured"}
        Attitude from gyro propagation (seed 001) or from the measured quaternion.
    encoder_resolution : float
        Gimbal-angle quantisation (rad); seed 001 Table 2 gives 0.0298 deg. 0 = exact.
    gains : dict or sequence of 3 floats
        ``{"K_p": ..., "K_i": ..., "K_w": ...}`` (``TuningResult.gains``) or
        ``(K_p, K_i, K_w)``, each >= 0.
    steering_options : dict, optional
        Options of the steering law (its builder's keywords: a singularity-robust
        weight, a null-motion gain ...); the pyramid's skew is passed by default.

    Returns
    -------
    Controller
        Gains ``K_p, K_i, K_w``; reference ``qc_w .. qc_z`` (the commanded attitude);
        logs the error quaternion, the filtered rate, the commanded torque and the yaw
        estimate.

    Raises
    ------
    InputError
        A Model that is not of a CMG testbed, an unknown option or a negative gain.

    Examples
    --------
    A 45 deg yaw step held for 5 s on the yaw CMG testbed:

    >>> import math
    >>> import airbearing as ab
    >>> model = ab.build_model("cmg-yaw")
    >>> controller = ab.cmg_attitude_controller(model, gains={"K_p": 6.0, "K_i": 0.001,
    ...                                                       "K_w": 6.0})
    >>> q_c = (math.cos(math.pi / 8), 0.0, 0.0, math.sin(math.pi / 8))  # 45 deg about z
    >>> run = ab.simulate(model, controller, duration=5.0, x0=model.x0(), reference=q_c)
    >>> round(math.degrees(run.state("yaw")[-1]), 0)  # deg, still settling
    44.0
    """
    fg = _checked_options(model, form, attitude, lowpass)
    gains = as_gains(gains, GAIN_NAMES)
    tb = model.testbed
    beta, h0, limit = tb.cmg.skew, tb.cmg.h0, tb.cmg.max_gimbal_rate
    opts = {"skew": beta, **(steering_options or {})}  # null motion needs the pyramid's skew
    steer = steering_function(steering, **opts)

    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", PID_STATES)  # filtered rate G (3), attitude estimate (4), integral (3)
    ref = ca.SX.sym("q_c", 4)
    g = ca.SX.sym("gains", 3)
    t = ca.SX.sym("t")
    Y = dict(zip(model.y_names, ca.vertsplit(y), strict=True))
    delta = ca.vertcat(*[Y[f"d{i}"] for i in range(1, 5)])
    if encoder_resolution > 0:
        delta = encoder_resolution * ca.floor(delta / encoder_resolution + 0.5)
    T_c, G, q_est, integral_next = quaternion_pid(model, Y, c, ref, g, fg=fg, attitude=attitude)
    A = jacobian_normalised(delta, beta)
    H = momentum_normalised(delta, beta)
    if form == "normalised":
        h_dot = -T_c - ca.cross(G, H)  # seed 001 eq. 11, per unit h0
    else:
        A = h0 * A
        h_dot = -T_c - ca.cross(G, h0 * H)
    if model.dof == 1:
        h_dot = ca.vertcat(0, 0, h_dot[2])  # the bearing holds roll and pitch
    dd = saturate_rates(steer(A, h_dot, delta, t), limit, rate_limit_mode)
    u = ca.vertcat(dd, 0, 0, 0)
    c_next = ca.vertcat(G, q_est, integral_next)
    extra = ca.vertcat(q_est, G, T_c, quat.yaw_of(q_est))
    fn = ca.Function("cmg_attitude", [y, c, ref, g, t], [u, c_next, extra],
                     ["y", "c", "ref", "gains", "t"], ["u", "c_next", "extra"])  # fmt: skip
    c0 = pid_c0()  # the attitude estimate starts at the identity quaternion
    return Controller(
        name=f"cmg_attitude_{steering}",
        function=fn,
        c0=c0,
        gains=gains,
        gain_names=GAIN_NAMES,
        ref_names=("qc_w", "qc_x", "qc_y", "qc_z"),
        extra_names=EXTRA_NAMES,
    )


#: Controller states of :func:`quaternion_pid`: filtered rate (3), attitude estimate (4),
#: integral of the quaternion error (3).
PID_STATES = 10


def quaternion_pid(model, Y: dict, c, ref, g, *, fg: float, attitude: str = "gyro"):
    """The quaternion PID of seed 001 as CasADi expressions, shared by every attitude loop.

    The gyro is low-pass filtered (seed 001 eq. 3); the attitude estimate is propagated with
    the previous filtered rate (eq. 21) or taken from the measurement (``attitude =
    "measured"``: the quaternion, or the yaw of a dof-1 bearing); the error quaternion
    ``q_err = q_c* (x) q`` (eq. 20) feeds ``T_c = -(K_p q_v + K_i int q_v dt + K_w G)``
    (eq. 19).

    Parameters
    ----------
    model : Model
        Its ``y_names`` name the entries of ``Y``; its testbed gives the sample time.
    Y : dict
        Measurement name -> CasADi scalar (rates rad/s, attitude).
    c : casadi.SX (PID_STATES,)
        ``G_prev`` (rad/s), the attitude estimate, the integral of ``q_v`` (s).
    ref : casadi.SX (4,)
        Commanded quaternion ``q_c`` (scalar first, need not be normalised).
    g : casadi.SX (3,)
        ``K_p, K_i, K_w`` in the unit of ``T_c`` (per unit of ``q_v``, ``q_v s``, rad/s).
    fg : float
        Low-pass factor ``f_g`` of eq. 3, 0 < f_g <= 1.
    attitude : {"gyro", "measured"}

    Returns
    -------
    T_c, G, q_est, integral_next : casadi.SX
        Commanded torque (3; the unit of the gains), filtered rate (3), attitude estimate
        (4) and the next integral (3): ``c_next = [G; q_est; integral_next]``.
    """
    dt = model.testbed.sensors.dt
    G_prev, q_prev, integral = c[0:3], c[3:7], c[7:10]
    if model.dof == 3:
        w_meas = ca.vertcat(Y["wx"], Y["wy"], Y["wz"])
    else:
        w_meas = ca.vertcat(0, 0, Y["wz"])
    if attitude == "measured" and model.dof == 3:
        q_est = ca.vertcat(Y["qw"], Y["qx"], Y["qy"], Y["qz"])
    elif attitude == "measured":
        q_est = quat.from_yaw(Y["yaw"])
    else:
        q_est = quat.normalize(quat.qmul(q_prev, quat.qexp(G_prev * dt)))  # seed 001 eq. 21
    G = (1 - fg) * G_prev + fg * w_meas  # seed 001 eq. 3
    q_err = quat.qmul(quat.qconj(quat.normalize(ref)), q_est)  # seed 001 eq. 20
    qv = q_err[1:4]
    integral_next = integral + qv * dt
    T_c = -(g[0] * qv + g[1] * integral_next + g[2] * G)  # seed 001 eq. 19
    return T_c, G, q_est, integral_next


def pid_c0() -> np.ndarray:
    """The PID's initial state: no filtered rate, the identity attitude, no integral."""
    c0 = np.zeros(PID_STATES)
    c0[3] = 1.0
    return c0


def _checked_options(model, form: str, attitude: str, lowpass: float | None) -> float:
    """The controller's options checked against the Model; the low-pass factor ``f_g``."""
    if model.kind != "cmg":
        raise InputError(
            f"the CMG attitude controller needs a kind = 'cmg' testbed, got '{model.kind}'"
        )
    if form not in ("normalised", "physical"):
        raise InputError(f"form '{form}': expected 'normalised' or 'physical'")
    if attitude not in ("gyro", "measured") or (attitude == "measured" and model.dof != 3):
        raise InputError(f"attitude '{attitude}': expected 'gyro', or 'measured' for dof 3")
    fg = model.testbed.sensors.lowpass if lowpass is None else lowpass
    if not 0 < fg <= 1:
        raise InputError(f"lowpass factor {fg}: expected 0 < f_g <= 1")
    return fg
