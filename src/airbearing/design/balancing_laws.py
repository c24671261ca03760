"""The three balancing laws as discrete Controllers: the seed-000 PID with its split
(:func:`pid_balancing_controller`), seed 004's projected Lyapunov law
(:func:`lyapunov_balancing_controller`) and the adaptive law of Chesi et al.
(:func:`adaptive_balancing_controller`), each a torque law wrapped with the measurement's
gravity direction, the real slider and magnetorquer blocks and the input layout.

The laws and their sign conventions: see :mod:`airbearing.design.balancing`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.balancing_gains import (
    ADAPTIVE_DEFAULT_GAINS,
    LYAPUNOV_DEFAULT_GAINS,
    SEED000_GAINS,
)
from airbearing.design.balancing_split import MECHANICAL, MIXED, PIDSplit
from airbearing.design.balancing_torques import (
    Z_HAT,
    dipole_for_torque,
    field_in_body,
    in_plane_pid,
    perp,
    slider_matrix,
)
from airbearing.design.controller import Controller
from airbearing.errors import InputError

__all__ = [
    "adaptive_balancing_controller",
    "lyapunov_balancing_controller",
    "pid_balancing_controller",
]


def _check_platform(model) -> None:
    tb = model.testbed
    if model.kind != "platform" or model.dof != 3:
        raise InputError(
            f"{tb.source}: balancing needs a kind = 'platform', dof = 3 testbed; "
            f"'{tb.name}' is kind = '{model.kind}', dof = {model.dof}"
        )
    if tb.masses is None:
        raise InputError(f"{tb.source}: testbed '{tb.name}' has no [masses] table (sliders)")


def _check_field(tb) -> np.ndarray:
    if tb.field is None:
        raise InputError(
            f"{tb.source}: testbed '{tb.name}' has no [field] table; magnetic damping needs the "
            "cage field (seed 000: 6e-4 T, vertical)"
        )
    b = tb.field.lab_vec
    if not np.all(np.isfinite(b)) or np.linalg.norm(b) == 0:
        raise InputError(
            f"{tb.source}: key 'field.lab' is {b.tolist()} T; the magnetorquers need a "
            "non-zero field"
        )
    return b


def _build(
    model,
    name,
    law,
    c_law0,
    gains,
    gain_names,
    *,
    uses_mag: bool,
    sliders: SliderActuator | None,
    magnetorquers: MagnetorquerActuator | None,
    slider_start,
    slider_zero,
    extra_law_names,
) -> Controller:
    """Wrap a torque law into a Controller with the actuator blocks and the u layout."""
    tb = model.testbed
    dt = tb.sensors.dt
    sliders = sliders or SliderActuator.from_testbed(tb)
    axes, masses = tb.masses.axes_matrix, tb.masses.mass_vec
    T = ca.DM(slider_matrix(axes, masses))
    b_lab = _check_field(tb) if uses_mag else np.zeros(3)
    if uses_mag:
        if tb.magnetorquers is None:
            raise InputError(
                f"{tb.source}: method '{name}' damps with magnetorquers, but testbed "
                f"'{tb.name}' has no [magnetorquers] table"
            )
        magnetorquers = magnetorquers or MagnetorquerActuator.from_testbed(tb)
    s_zero = np.zeros(3) if slider_zero is None else np.asarray(slider_zero, float).reshape(3)
    s_start = s_zero if slider_start is None else np.asarray(slider_start, float).reshape(3)
    sliders.state0(s_zero)  # the law's reference must itself lie within the travel
    act0 = sliders.state0(s_start)
    nl = len(c_law0)

    y = ca.SX.sym("y", model.ny)
    c = ca.SX.sym("c", nl + act0.size)
    ref = ca.SX.sym("ref", 0)
    g = ca.SX.sym("gains", len(gains))
    t = ca.SX.sym("t")
    Y = dict(zip(model.y_names, ca.vertsplit(y), strict=True))
    q = ca.vertcat(Y["qw"], Y["qx"], Y["qy"], Y["qz"])
    w = ca.vertcat(Y["wx"], Y["wy"], Y["wz"])
    g_meas = ca.vertcat(Y["gx"], Y["gy"], Y["gz"])
    g_hat = g_meas / ca.norm_2(g_meas)
    tau_sl, tau_mag, c_law_next, extra_law = law(q, w, g_hat, c[:nl], g, dt)

    ds = ca.mtimes(T, ca.cross(g_hat, tau_sl) / tb.gravity)  # seed 000 eq. 5, seed 004 eq. 13
    s_cmd = ca.DM(s_zero) + ds
    s_held, act_next, motor = sliders.function(dt)(s_cmd, c[nl:])
    if uses_mag:
        b_body = field_in_body(b_lab, g_hat, q)
        d = magnetorquers.function()(dipole_for_torque(tau_mag, b_body))  # seed 000 eq. 7
    else:
        d = ca.SX.zeros(3)
    u = ca.vertcat(s_held, d, ca.DM(b_lab), ca.SX.zeros(3))
    g_perp = ca.norm_2(g_hat[0:2])
    extra = ca.vertcat(motor, s_cmd, tau_sl, tau_mag, g_perp, extra_law)
    fn = ca.Function(
        f"balance_{name}",
        [y, c, ref, g, t],
        [u, ca.vertcat(c_law_next, act_next), extra],
        ["y", "c", "ref", "gains", "t"],
        ["u", "c_next", "extra"],
    )
    extra_names = (
        ("motor1", "motor2", "motor3", "s1_cmd", "s2_cmd", "s3_cmd")
        + ("tau_sl_x", "tau_sl_y", "tau_sl_z", "tau_mag_x", "tau_mag_y", "tau_mag_z")
        + ("g_perp_meas",)
        + tuple(extra_law_names)
    )
    return Controller(
        name=f"balance_{name}",
        function=fn,
        c0=np.concatenate([np.asarray(c_law0, float), act0]),
        gains=np.asarray(gains, dtype=float),
        gain_names=tuple(gain_names),
        ref_names=(),
        extra_names=extra_names,
    )


def pid_balancing_controller(
    model,
    *,
    split: PIDSplit = MIXED,
    gains=SEED000_GAINS,
    sliders: SliderActuator | None = None,
    magnetorquers: MagnetorquerActuator | None = None,
    slider_start=None,
    slider_zero=None,
) -> Controller:
    """The in-plane PID of seed 000 (eq. 3) with its terms shared as ``split`` says.

    Parameters
    ----------
    model : Model
        A ``kind = "platform"``, dof 3 Model.
    split : PIDSplit
        :data:`MECHANICAL` (seed 000 eq. 8) or :data:`MIXED` (eqs. 5 and 7), or any other.
    gains : (K_p N m, K_d N m s, K_d K_i N m/s)
        Default seed 000 Tables 1-2.
    sliders, magnetorquers : actuator blocks
        Default: the testbed's real actuators (:mod:`airbearing.design.actuators`).
    slider_start, slider_zero : (3,) m
        Where the sliders are at the start, and the positions the law's displacements are
        measured from (default zero, the rail origin: seed 000 eq. 5 gives the slider
        positions ``r_b`` themselves); ``slider_start`` defaults to ``slider_zero``.

    Notes
    -----
    State ``c``: the integral ``int g_hat x z_hat dt`` (3, s) then the slider block's
    state. The cage field ``[field] lab`` is output only when the magnetorquers act (seed
    000 switched the cage on for the mixed tests).
    """
    if not isinstance(split, PIDSplit):
        raise InputError(f"split {split!r}: expected a PIDSplit (e.g. MECHANICAL or MIXED)")
    _check_platform(model)
    if len(gains) != 3:
        raise InputError(f"gains {gains}: expected K_p, K_d, K_d*K_i")

    def law(q, w, g_hat, c, g, dt):
        e = ca.cross(g_hat, Z_HAT)
        integral = c + e * dt  # i = (int g_hat dt) x z_hat, seed 000 eq. 3
        tau_p, tau_i, tau_d = in_plane_pid(g_hat, w, integral, g)
        sl, mg = split.torques(tau_p, tau_i, tau_d)
        return sl, mg, integral, ca.vertcat(e)

    name = {MECHANICAL: "mechanical", MIXED: "mixed"}.get(split, "pid")
    return _build(
        model, name, law, np.zeros(3), gains, ("K_p", "K_d", "K_dK_i"),
        uses_mag=split.uses_magnetorquers, sliders=sliders, magnetorquers=magnetorquers,
        slider_start=slider_start, slider_zero=slider_zero, extra_law_names=("e_x", "e_y", "e_z"),
    )  # fmt: skip


def lyapunov_balancing_controller(
    model,
    *,
    gains=LYAPUNOV_DEFAULT_GAINS,
    inertia=None,
    full: bool = False,
    sliders: SliderActuator | None = None,
    slider_start=None,
    slider_zero=None,
) -> Controller:
    """The projected Lyapunov law of seed 004 (eq. 51, or eq. 34 with ``full=True``).

    ``tau = -K q4 q_ep - P w_p - P K_I z_p [+ P_p (w x J w)]`` with ``q_e`` the vector part
    of the measured attitude quaternion (target: identity, body z up; seed 004 eq. 15),
    ``z = int K q4 q_e dt + J w`` (eq. 15), projections ``P_p = I - g_hat g_hat^T``
    (eqs. 25-31). All of it is in-plane, so the sliders carry it (seed 004 eq. 13).

    Parameters
    ----------
    gains : (K N m, P N m s, K_I 1/(N m s))
        Default :data:`LYAPUNOV_DEFAULT_GAINS` (matched to the seed-000 PID).
    inertia : (3, 3) kg m^2, optional
        The controller's inertia for ``z``; default the testbed's nominal inertia.
    full : bool
        Keep the ``P_p (w x J w)`` term of eq. 34.
    slider_start, slider_zero : (3,) m
        As :func:`pid_balancing_controller` (seed 004 eq. 13 gives positions too).

    Notes
    -----
    ``q_e`` includes yaw: on a spinning platform the law's restoring direction turns with
    half the yaw angle, as in the seed. State ``c``: ``int K q4 q_e dt`` (3) then sliders.
    """
    _check_platform(model)
    if len(gains) != 3:
        raise InputError(f"gains {gains}: expected K, P, K_I")
    J = ca.DM(model.testbed.body.inertia_matrix if inertia is None else np.asarray(inertia))

    def law(q, w, g_hat, c, g, dt):
        K, P, KI = g[0], g[1], g[2]
        q4, qe = q[0], q[1:4]
        zint = c + K * q4 * qe * dt  # seed 004 eq. 15 (integral part)
        z = zint + ca.mtimes(J, w)
        qep, wp, zp = perp(qe, g_hat), perp(w, g_hat), perp(z, g_hat)  # eqs. 26, 28, 31
        tau = -K * q4 * qep - P * wp - P * KI * zp  # seed 004 eq. 51
        if full:
            tau = tau + perp(ca.cross(w, ca.mtimes(J, w)), g_hat)  # seed 004 eq. 34
        return tau, ca.SX.zeros(3), zint, ca.norm_2(qep)

    return _build(
        model, "lyapunov", law, np.zeros(3), gains, ("K", "P", "K_I"),
        uses_mag=False, sliders=sliders, magnetorquers=None, slider_start=slider_start,
        slider_zero=slider_zero, extra_law_names=("q_ep_norm",),
    )  # fmt: skip


def adaptive_balancing_controller(
    model,
    *,
    gains=None,
    sliders: SliderActuator | None = None,
    slider_start=None,
    slider_zero=None,
) -> Controller:
    """The adaptive balancing law of Chesi et al. 2014 (reference 12 of seed 000).

    ``tau = -Phi r_hat - k_p P_p w`` with ``Phi r = m r x g`` (the gravity torque of an
    offset ``r``, seed 000 eq. 1) and ``r_hat(k+1) = r_hat(k) + dt gamma Phi^T w``,
    ``Phi^T w = m g x w``. The sliders make ``tau`` (seed 004 eq. 13); in the plane they
    sit at ``-m r_hat / m_i`` plus the damping displacement.

    Parameters
    ----------
    gains : (k_p N m s, k_theta N m/rad)
        ``gamma = k_theta / (m |g|)^2``; default :data:`ADAPTIVE_DEFAULT_GAINS`.
    slider_start, slider_zero : (3,) m
        As :func:`pid_balancing_controller`.

    Notes
    -----
    State ``c``: ``r_hat`` (3, m, the offset with the sliders at ``slider_zero``) then sliders.
    Extra: ``r_hat_x..z``.

    In body axes gravity turns as ``g' = g x w``, so ``Phi^T w = m g x w = m g'`` and the
    estimate is ``r_hat(t) = r_hat(0) + gamma m (g(t) - g(0))``: the law learns only as
    far as the platform's gravity direction moves. Near level it acts as a tilt
    stiffness ``gamma m^2 |g|^2``; a platform at rest in its rest position (CM below the
    CR) is already an equilibrium of it and stays there.
    """
    _check_platform(model)
    tb = model.testbed
    gains = ADAPTIVE_DEFAULT_GAINS if gains is None else gains
    if len(gains) != 2:
        raise InputError(f"gains {gains}: expected k_p, k_theta")
    mass, grav = tb.body.mass, tb.gravity

    def law(q, w, g_hat, c, g, dt):
        kp, ktheta = g[0], g[1]
        gamma = ktheta / (mass * grav) ** 2
        g_vec = grav * g_hat
        tau = -mass * ca.cross(c, g_vec) - kp * perp(w, g_hat)  # -Phi r_hat - k_p P_p w
        r_next = c + dt * gamma * mass * ca.cross(g_vec, w)  # r_hat' = gamma Phi^T w
        return tau, ca.SX.zeros(3), r_next, r_next

    return _build(
        model, "adaptive", law, np.zeros(3), gains, ("k_p", "k_theta"),
        uses_mag=False, sliders=sliders, magnetorquers=None, slider_start=slider_start,
        slider_zero=slider_zero, extra_law_names=("r_hat_x", "r_hat_y", "r_hat_z"),
    )  # fmt: skip
