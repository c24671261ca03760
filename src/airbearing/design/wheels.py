"""Reaction-wheel allocation and the wheel attitude loop, as CasADi Functions.

Wheel ``i`` spins about the unit vector ``a_i`` (the rows of ``wheels.axes``, body axes);
a motor torque ``tau_m_i`` spins the wheel up and turns the body the other way: the torque
on the body is ``-sum_i tau_m_i a_i = -A^T tau_m`` (FORMATS.md, reaction wheels).

*Allocation.* A wanted body torque ``T`` on the free axes (z on a dof-1 bearing, all three
on dof 3) is met by the least-norm motor torques ``tau_m = -pinv(A_f^T) T``, with ``A_f``
the columns of ``A`` on the free axes. It is exact while no wheel saturates.

*Null space.* A set with more wheels than free axes has motor torques that exchange no
torque with the body: ``N = I - pinv(A_f^T) A_f^T`` projects on them (``A_f^T N = 0``).
The wheel-speed management ``tau_n = -k_b Iw N (W - W_b)`` (``Iw`` the mean wheel inertia)
drives the wheel speeds' null-space part to that of a bias ``W_b``: the wheels are kept
away from zero speed, where the bearing's Coulomb friction changes sign, and, with a bias
below ``max_speed``, away from the speed limit. The default bias is ``bias_fraction``
of ``max_speed`` along the null space's first direction (scaled so its largest entry is
1): on a symmetric 4-wheel pyramid every wheel then runs at the same ``|W_i|``.

*Saturation.* The total motor torque is limited to ``max_torque``; ``"scale"`` (default)
scales every wheel's torque by the same factor when the largest passes the limit, so the
torque keeps its direction (as seed 001 eq. 4 scales gimbal rates), ``"clip"`` clips each
wheel on its own. The controller logs ``wsat``, the largest ``|tau_m_i| / max_torque``
asked for: above 1 the wheels were saturated.

*Command.* ``command = "torque"``: the logged command ``wc_i`` is the motor torque (N m).
``command = "speed"``: the wheel's own driver holds a speed, ``tau_m_i = Iw_i (wc_i - W_i) /
speed_loop_tau``; the controller integrates the wanted torque into a target speed,
``wc_i <- wc_i + dt tau_m_i / Iw_i`` (held within ``+-max_speed``), which is what the
driver sees: a ramp whose slope is the wanted wheel acceleration. The driver then gives the
wanted torque after a lag of about ``speed_loop_tau`` (in the linear loop through the
plant's wheel states).

*Momentum dumping.* On a rig with magnetorquers in a cage field, the dipole
``m = k_d (h x b) / |b|^2`` (``b`` the field in body axes from the attitude estimate,
``h = A^T Iw (W - W_b)`` the wheels' excess momentum in body axes) gives the external
torque ``m x b = -k_d h_perp``, which the attitude loop passes on to the wheels: their
momentum across the field decays at the rate ``k_d`` (the part along ``b`` cannot be
dumped). The dipole is scaled to ``max_dipole`` keeping its direction.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.attitude import PID_STATES, pid_c0, quaternion_pid
from airbearing.design.controller import Controller
from airbearing.errors import InputError
from airbearing.io.coerce import as_gains

__all__ = [
    "WHEEL_GAIN_NAMES",
    "WHEEL_EXTRA_NAMES",
    "free_axes",
    "allocation",
    "allocation_function",
    "bias_speeds",
    "saturate_torques",
    "dump_dipole",
    "wheel_attitude_controller",
    "has_wheels",
    "default_wheel_gains",
    "wheel_bias",
    "trim_wheel_speeds",
]

#: The wheel loop's gains: ``T_c = -(K_p q_v + K_i int q_v dt + K_w G)`` in N m
#: (K_p N m, K_i N m/s, K_w N m s), seed 001 eq. 19 in physical units.
WHEEL_GAIN_NAMES = ("K_p", "K_i", "K_w")
#: Shape of the default design (:func:`default_wheel_gains`): damping of the placed pair
#: and the integral pole's ratio to its speed.
DEFAULT_DAMPING, DEFAULT_INTEGRAL_RATIO = 0.9, 0.001
#: Default speed of the bias management, 1/s (a 20 s time constant, well below the
#: attitude loop's bandwidth).
BIAS_GAIN = 0.05
#: Default bias, a fraction of ``max_speed``.
BIAS_FRACTION = 0.2
#: Default dumping rate, 1/s.
DUMP_GAIN = 0.02
_RANK_TOL = 1e-9


def default_wheel_gains(testbed) -> dict:
    """Starting gains of a wheel rig before ``airbearing gains`` tunes them: K_p, K_i, K_w.

    The rigid body ``J s^2`` (``J`` the largest principal inertia on the free axes)
    closed by the PID has its poles at ``(s^2 + 2 zeta w s + w^2)(s + r w)`` with
    ``zeta = 0.9``, ``r = 0.001`` and the speed ``w = sqrt(max_torque / (J pi/2))`` (rad/s),
    at which a 90 deg step asks the wheels for about ``max_torque`` (``K_p q_v ~ 2 J w^2
    theta / 2``); at most a tenth of the Nyquist frequency.
    """
    J = np.asarray(testbed.body.inertia_matrix, float)
    Jm = float(J[2, 2] if testbed.body.dof == 1 else np.linalg.eigvalsh(J).max())
    w = min(
        np.sqrt(testbed.wheels.max_torque / (Jm * np.pi / 2)), 0.1 * np.pi * testbed.sensors.rate
    )
    z, a = DEFAULT_DAMPING, DEFAULT_INTEGRAL_RATIO * w
    return {
        "K_p": 2 * Jm * (w * w + 2 * z * w * a),
        "K_i": 2 * Jm * w * w * a,
        "K_w": Jm * (2 * z * w + a),
    }


def has_wheels(testbed) -> bool:
    """True when the testbed has a ``[wheels]`` table (a reaction-wheel rig)."""
    return getattr(testbed, "wheels", None) is not None


def free_axes(dof: int) -> list[int]:
    """Body axes the bearing lets turn: ``[2]`` (z) on dof 1, ``[0, 1, 2]`` on dof 3."""
    return [2] if dof == 1 else [0, 1, 2]


def allocation(axes, dof: int) -> tuple[np.ndarray, np.ndarray]:
    """The allocation and null-space projector of a wheel set.

    Parameters
    ----------
    axes : array (n, 3)
        Spin axes ``a_i`` (unit vectors, body axes), one row per wheel.
    dof : {1, 3}
        Free axes of the bearing.

    Returns
    -------
    M : ndarray (n, 3)
        Motor torques per wanted body torque: ``tau_m = M T`` gives ``-A^T tau_m = T`` on
        the free axes (columns of the axes the bearing holds are zero). N m per N m.
    N : ndarray (n, n)
        Projector on the motor torques that exchange no torque with the body on the free
        axes (``A_f^T N = 0``); zero when the set is not redundant.

    Raises
    ------
    InputError
        The wheels cannot make torque about every free axis.
    """
    A = np.asarray(axes, dtype=float)
    free = free_axes(dof)
    Af = A[:, free]  # n x k
    if np.linalg.matrix_rank(Af, tol=_RANK_TOL) < len(free):
        raise InputError(
            f"wheels.axes {A.tolist()}: the wheels cannot make torque about every free axis "
            f"({'z' if dof == 1 else 'x, y and z'}); expected axes spanning them"
        )
    P = np.linalg.pinv(Af.T)  # n x k, Af^T P = I
    M = np.zeros((A.shape[0], 3))
    M[:, free] = -P
    N = np.eye(A.shape[0]) - P @ Af.T
    N[np.abs(N) < 1e-14] = 0.0
    return M, N


def bias_speeds(axes, dof: int, speed: float) -> np.ndarray:
    """The bias of the wheel-speed management, rad/s per wheel.

    ``speed`` times the null space's first direction (the right singular vector of
    ``A_f^T`` of the smallest singular value), scaled so its largest entry is 1 and its
    first non-zero entry is positive; zeros when the set is not redundant.
    """
    A = np.asarray(axes, dtype=float)
    Af = A[:, free_axes(dof)]
    n = A.shape[0]
    if n <= Af.shape[1]:
        return np.zeros(n)
    _, _, Vt = np.linalg.svd(Af.T)
    v = Vt[-1]
    v = v / np.abs(v).max()
    nz = np.nonzero(np.abs(v) > 1e-12)[0]
    if v[nz[0]] < 0:
        v = -v
    v[np.abs(v) < 1e-12] = 0.0
    return speed * v


def saturate_torques(tau, limit: float, mode: str = "scale"):
    """Motor torques limited to ``limit`` (N m): ``"scale"`` keeps the direction (every
    wheel scaled by the same factor), ``"clip"`` clips each wheel on its own."""
    if mode not in ("scale", "clip"):
        raise InputError(f"torque limiting mode '{mode}': expected 'scale' or 'clip'")
    if mode == "scale":
        peak = ca.mmax(ca.fabs(tau))
        return ca.if_else(peak > limit, tau * (limit / peak), tau)
    return ca.fmin(ca.fmax(tau, -limit), limit)


def allocation_function(
    axes,
    dof: int,
    inertia,
    max_torque: float,
    *,
    bias_gain: float = BIAS_GAIN,
    bias=None,
    saturation: str = "scale",
) -> ca.Function:
    """The wheel allocation as a CasADi Function ``(T[3], W[n]) -> (tau_m[n], wsat)``.

    ``tau_m = M T - k_b Iw N (W - W_b)`` (:func:`allocation`; ``Iw`` the mean wheel
    inertia), limited to ``max_torque`` by :func:`saturate_torques`; ``wsat`` is the
    largest ``|tau_m_i| / max_torque`` asked for (above 1: saturated).

    Parameters
    ----------
    axes : array (n, 3)
        Spin axes, body axes.
    dof : {1, 3}
        Free axes of the bearing.
    inertia : array (n,)
        Spin-axis inertias, kg m^2.
    max_torque : float
        N m, each wheel.
    bias_gain : float
        1/s, null-space speed management (0: off).
    bias : array (n,), optional
        rad/s, bias speeds ``W_b`` (default zeros).
    saturation : {"scale", "clip"}
    """  # fmt: skip
    A = np.asarray(axes, dtype=float)
    n = A.shape[0]
    M, N = allocation(A, dof)
    Iw = np.asarray(inertia, dtype=float).reshape(n)
    W_b = np.zeros(n) if bias is None else np.asarray(bias, dtype=float).reshape(n)
    T = ca.SX.sym("T", 3)
    W = ca.SX.sym("W", n)
    tau = ca.mtimes(ca.DM(M), T)
    if bias_gain > 0 and np.any(N != 0):
        tau = tau - bias_gain * float(Iw.mean()) * ca.mtimes(ca.DM(N), W - ca.DM(W_b))
    limit = float(max_torque)
    wsat = ca.mmax(ca.fabs(tau)) / limit
    tau = saturate_torques(tau, limit, saturation)
    return ca.Function("wheel_allocation", [T, W], [tau, wsat], ["T", "W"], ["tau_m", "wsat"])


def dump_dipole(h, b_body, gain: float, max_dipole: float):
    """Momentum-dumping dipole ``m = gain (h x b) / |b|^2`` (A m^2), scaled to ``max_dipole``.

    ``h`` (N m s) the wheel momentum to dump, ``b_body`` (T) the field in body axes. The
    torque ``m x b = -gain h_perp`` (N m) takes away the part of ``h`` across the field.
    """
    m = gain * ca.cross(h, b_body) / ca.fmax(ca.sumsqr(b_body), 1e-30)
    peak = ca.mmax(ca.fabs(m))
    return ca.if_else(peak > max_dipole, m * (max_dipole / peak), m)


#: What the wheel controller logs each sample: attitude estimate, filtered rate, commanded
#: body torque, the estimate's yaw, the largest wheel torque asked for per max_torque.
WHEEL_EXTRA_NAMES = ("qe_w", "qe_x", "qe_y", "qe_z", "G_x", "G_y", "G_z", "Tc_x", "Tc_y",
                     "Tc_z", "yaw_est", "wsat")  # fmt: skip


def wheel_attitude_controller(
    model,
    *,
    gains=None,
    lowpass: float | None = None,
    attitude: str = "gyro",
    saturation: str = "scale",
    bias_gain: float = BIAS_GAIN,
    bias_fraction: float = BIAS_FRACTION,
    bias=None,
    dump_gain: float | None = None,
    gyroscopic: bool = True,
) -> Controller:
    """The quaternion attitude loop on reaction wheels as a discrete CasADi block.

    Each sample: the quaternion PID of seed 001 (eqs. 3, 19-21, shared with the CMG loop:
    :func:`~airbearing.design.attitude.quaternion_pid`) gives the wanted torque ``T_c``
    (N m); the wheels are asked for ``-T_c - G x h_w`` (the gyroscopic torque of their
    momentum ``h_w = A^T Iw W`` cancelled, as seed 001 eq. 11 does for the CMGs), allocated
    by the pseudo-inverse, plus the null-space speed management, limited to
    ``max_torque``; with magnetorquers in a cage field, the dumping dipole. See the module
    docstring for each part.

    Parameters
    ----------
    model : Model
        A testbed with ``[wheels]`` and a rate gyro.
    gains : dict or sequence of 3 float, optional
        ``K_p`` (N m), ``K_i`` (N m/s), ``K_w`` (N m s), each >= 0; default
        :func:`default_wheel_gains`.
    lowpass : float, optional
        ``f_g`` of seed 001 eq. 3; default ``sensors.lowpass``.
    attitude : {"gyro", "measured"}
        Attitude propagated from the gyro (seed 001 eq. 21) or the measured one.
    saturation : {"scale", "clip"}
        How the motor torques are limited to ``max_torque``.
    bias_gain : float
        1/s, speed of the null-space wheel-speed management (0: off).
    bias_fraction : float
        Default bias speed as a fraction of ``max_speed``, 0 <= f < 1.
    bias : sequence of n float, optional
        rad/s, the bias speeds themselves (only their null-space part acts).
    dump_gain : float, optional
        1/s, momentum-dumping rate; default :data:`DUMP_GAIN` on a rig with magnetorquers
        and a field, else 0.
    gyroscopic : bool
        Cancel the gyroscopic torque of the wheels' momentum.

    Returns
    -------
    Controller
        ``(y, c, ref, gains, t) -> (u, c_next, extra)``; ``ref`` the commanded quaternion,
        ``extra`` :data:`WHEEL_EXTRA_NAMES`.
    """
    tb = model.testbed
    if not has_wheels(tb):
        raise InputError(f"{tb.source}: testbed '{tb.name}' has no [wheels] table")
    if attitude not in ("gyro", "measured"):
        raise InputError(f"attitude '{attitude}': expected 'gyro' or 'measured'")
    fg = tb.sensors.lowpass if lowpass is None else lowpass
    if not 0 < fg <= 1:
        raise InputError(f"lowpass factor {fg}: expected 0 < f_g <= 1")
    if not (0 <= bias_fraction < 1):
        raise InputError(f"bias_fraction {bias_fraction}: expected 0 <= f < 1 of max_speed")
    for name, v in (("bias_gain", bias_gain), ("dump_gain", dump_gain)):
        if v is not None and not (np.isfinite(v) and v >= 0):
            raise InputError(f"{name} {v}: expected a rate >= 0 in 1/s")
    gains = as_gains(default_wheel_gains(tb) if gains is None else gains, WHEEL_GAIN_NAMES)
    wh = tb.wheels
    n, dt = wh.n, tb.sensors.dt
    axes = np.asarray(wh.axes_matrix, float)
    Iw = np.asarray(wh.inertia_vec, float)
    W_b = wheel_bias(tb, bias_fraction, bias)
    mag = tb.magnetorquers is not None and tb.field is not None and model.kind == "platform"
    k_d = (DUMP_GAIN if mag else 0.0) if dump_gain is None else float(dump_gain)
    if k_d > 0 and not mag:
        raise InputError(
            f"dump_gain {k_d}: testbed '{tb.name}' has no magnetorquers in a cage field"
        )
    speed = wh.command == "speed"

    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", PID_STATES + (n if speed else 0))
    ref = ca.SX.sym("q_c", 4)
    g = ca.SX.sym("gains", 3)
    t = ca.SX.sym("t")
    Y = dict(zip(model.y_names, ca.vertsplit(y), strict=True))
    T_c, G, q_est, integral_next = quaternion_pid(
        model, Y, c[:PID_STATES], ref, g, fg=fg, attitude=attitude
    )
    W = ca.vertcat(*[Y[f"ws{i}"] for i in range(1, n + 1)])
    h_w = ca.mtimes(ca.DM(axes.T), Iw * W)  # N m s, body axes
    T_want = T_c + (ca.cross(G, h_w) if gyroscopic else 0)
    # -A^T tau = T_c + G x h_w: the wheels' momentum rate is -T_c - G x h_w (seed 001 eq. 11)
    alloc = allocation_function(axes, model.dof, Iw, wh.max_torque, bias_gain=bias_gain,
                                bias=W_b, saturation=saturation)  # fmt: skip
    tau, wsat = alloc(T_want, W)
    u = ca.SX.zeros(model.nu)
    wc_idx = model.index([f"wc{i}" for i in range(1, n + 1)], "u")
    c_next = [G, q_est, integral_next]
    if speed:
        target = c[PID_STATES:] + dt * tau / Iw
        target = ca.fmin(ca.fmax(target, -wh.max_speed), wh.max_speed)
        cmd = target
        c_next.append(target)
    else:
        cmd = tau
    for j, i in enumerate(wc_idx):
        u[i] = cmd[j]
    if model.kind == "platform" and tb.field is not None:
        b_lab = np.asarray(tb.field.lab_vec, float)
        for j, i in enumerate(model.index(["bx_lab", "by_lab", "bz_lab"], "u")):
            u[i] = b_lab[j]
        if k_d > 0:
            h_x = ca.mtimes(ca.DM(axes.T), Iw * (W - W_b))
            m = dump_dipole(h_x, quat.rotate_inverse(q_est, ca.DM(b_lab)), k_d,
                            tb.magnetorquers.max_dipole)  # fmt: skip
            for j, i in enumerate(model.index(["mx", "my", "mz"], "u")):
                u[i] = m[j]
    extra = ca.vertcat(q_est, G, T_c, quat.yaw_of(q_est), wsat)
    fn = ca.Function("wheel_attitude", [y, c, ref, g, t], [u, ca.vertcat(*c_next), extra],
                     ["y", "c", "ref", "gains", "t"], ["u", "c_next", "extra"])  # fmt: skip
    c0 = pid_c0()
    if speed:
        c0 = np.concatenate([c0, np.asarray(wh.speeds_vec, float)])
    return Controller(
        name=f"wheel_attitude_{wh.command}",
        function=fn,
        c0=c0,
        gains=gains,
        gain_names=WHEEL_GAIN_NAMES,
        ref_names=("qc_w", "qc_x", "qc_y", "qc_z"),
        extra_names=WHEEL_EXTRA_NAMES,
    )


def wheel_bias(testbed, bias_fraction: float = BIAS_FRACTION, bias=None) -> np.ndarray:
    """The bias speeds ``W_b`` (rad/s per wheel) of a testbed's wheel set: ``bias`` when
    given, else ``bias_fraction * max_speed`` along the null space (:func:`bias_speeds`)."""
    wh = testbed.wheels
    if bias is not None:
        b = np.asarray(bias, dtype=float).reshape(-1)
        if b.shape != (wh.n,) or not np.all(np.isfinite(b)):
            raise InputError(f"bias {list(np.ravel(bias))}: expected {wh.n} speeds in rad/s")
        if np.any(np.abs(b) >= wh.max_speed):
            raise InputError(
                f"bias {b.tolist()}: expected speeds below wheels.max_speed = {wh.max_speed} rad/s"
            )
        return b
    return bias_speeds(wh.axes_matrix, testbed.body.dof, bias_fraction * wh.max_speed)


def trim_wheel_speeds(testbed, bias_fraction: float = BIAS_FRACTION, bias=None) -> np.ndarray:
    """Wheel speeds (rad/s) at which the loop is at rest: the testbed's ``speeds`` with
    their null-space part moved to the bias's (``W0 + N (W_b - W0)``)."""
    wh = testbed.wheels
    _, N = allocation(wh.axes_matrix, testbed.body.dof)
    W0 = np.asarray(wh.speeds_vec, float)
    return W0 + N @ (wheel_bias(testbed, bias_fraction, bias) - W0)
