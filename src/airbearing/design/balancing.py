"""Automatic in-plane balancing laws of seeds 000 and 004, as discrete CasADi controllers.

The laws
    * ``pid``: seed 000 eq. 3, ``tau = K_p g_hat x z_hat + K_d K_i i_perp - K_d w_perp`` with
      ``i = (int g_hat dt) x z_hat``; which actuator carries which term is a
      :class:`PIDSplit` (``MECHANICAL``: seed 000 eq. 8; ``MIXED``: seed 000 eqs. 5 and 7).
    * ``lyapunov``: the projected law of seed 004 eq. 51 (eq. 34 without the
      ``P_p (w x J w)`` term, as seed 004 simulated and flew it), with the integral state
      ``z = int K q4 q_e dt + J w`` of eq. 15 projected by eq. 31.
    * ``adaptive``: Chesi et al. (J. Guid. Control Dyn. 37(1), 2014; reference 12 of seed
      000): ``tau = -Phi r_hat - k_p P_p w`` with ``Phi r = m r x g`` and the offset estimate
      adapted by ``r_hat' = gamma Phi^T w`` (from ``V = w^T J w / 2 + |r - r_hat|^2 / (2 gamma)``,
      ``V' = -k_p |w_perp|^2``).

Sign conventions. ``g_hat`` is the measured unit gravity direction in body axes (pointing
down: ``[0, 0, -1]`` when level), ``z_hat = [0, 0, 1]``. The operators of seed 000 eqs. 3-8
are lost in the seed's text; the signs here are the ones that make each term act as
named: for a tilt ``theta`` about body x, ``g_hat x z_hat = [-sin theta, 0, 0]``, so
``+K_p g_hat x z_hat`` restores, the integral term acts with the same sign and the
derivative term opposes ``w``.

Every controller has the :mod:`airbearing.design.controller` interface
``(y, c, ref, gains, t) -> (u, c_next, extra)`` with ``y = qw qx qy qz wx wy wz gx gy gz``
(noisy) and ``u = s1 s2 s3 mx my mz bx_lab by_lab bz_lab tau_x tau_y tau_z``. The slider
command is the controller's displacement added to the sliders' position at the start of
the run (stepper motors count steps from where they start), and passes through the real
actuators of :mod:`airbearing.design.actuators`, whose states live in ``c``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import wraps
from typing import ClassVar

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.design.actuators import MagnetorquerActuator, SliderActuator
from airbearing.design.controller import Controller
from airbearing.errors import InputError

__all__ = [
    "ACTUATORS",
    "ADAPTIVE_DEFAULT_GAINS",
    "BalancingGains",
    "LYAPUNOV_DEFAULT_GAINS",
    "METHODS",
    "MECHANICAL",
    "MIXED",
    "PIDSplit",
    "SEED000_GAINS",
    "TILT_INTEGRAL_RATE",
    "adaptive_balancing_controller",
    "balancing_controller",
    "default_split",
    "dipole_for_torque",
    "field_in_body",
    "in_plane_pid",
    "lyapunov_balancing_controller",
    "pid_balancing_controller",
    "slider_matrix",
    "tilt_pid_gains",
    "lyapunov_gains_from_pid",
    "slider_torque",
    "torque_to_sliders",
]


@dataclass(frozen=True)
class BalancingGains:
    """The in-plane PID gains of the balancing loop (seed 000 eq. 3), the one gains type.

    A sequence ``(K_p, K_d, K_dK_i)`` (unpacking, ``gains[0]``, ``np.asarray(gains)``)
    and, by name, what ``airbearing gains --loop balancing --json`` writes under
    ``gains`` (``gains["K_dK_i"]``, :meth:`to_json`, :meth:`from_json`).

    Attributes
    ----------
    K_p : float
        N m (per unit of in-plane ``g_hat``).
    K_d : float
        N m s.
    K_dK_i : float
        N m/s, the product ``K_d K_i``.

    Examples
    --------
    >>> from airbearing.design.balancing import SEED000_GAINS, BalancingGains
    >>> SEED000_GAINS.to_json()
    {'K_p': 0.001, 'K_d': 0.0018, 'K_dK_i': 2e-05}
    >>> kp, kd, kdki = BalancingGains.from_json({"K_p": 1, "K_d": 2, "K_dK_i": 3})
    >>> kdki
    3.0
    """

    K_p: float
    K_d: float
    K_dK_i: float

    #: JSON names, in the order of the sequence.
    names: ClassVar[tuple[str, ...]] = ("K_p", "K_d", "K_dK_i")

    def __post_init__(self):
        for n in self.names:
            v = getattr(self, n)
            try:
                v = float(v)
            except (TypeError, ValueError):
                raise InputError(f"gains {n}={v!r}: expected a number") from None
            if not math.isfinite(v):
                raise InputError(f"gains {n}={v}: expected a finite number")
            object.__setattr__(self, n, v)

    @classmethod
    def from_json(cls, data) -> BalancingGains:
        """From ``{"K_p", "K_d", "K_dK_i"}`` (the gains JSON) or a sequence of three."""
        if isinstance(data, BalancingGains):
            return data
        if isinstance(data, Mapping):
            missing = [n for n in cls.names if n not in data]
            unknown = [k for k in data if k not in cls.names]
            if missing or unknown:
                raise InputError(
                    f"gains {dict(data)}: expected the keys {list(cls.names)} "
                    f"(missing {missing}, unknown {unknown})"
                )
            return cls(*(data[n] for n in cls.names))
        vals = list(np.atleast_1d(np.asarray(data, dtype=float)))
        if len(vals) != 3:
            raise InputError(f"gains {vals}: expected K_p, K_d, K_d*K_i")
        return cls(*vals)

    def to_json(self) -> dict:
        """``{"K_p", "K_d", "K_dK_i"}`` (SI), the ``gains`` of the gains JSON."""
        return {n: getattr(self, n) for n in self.names}

    @property
    def K_i(self) -> float:
        """1/s, the integral rate ``K_dK_i / K_d``."""
        return self.K_dK_i / self.K_d if self.K_d else math.inf

    def keys(self):
        return self.to_json().keys()

    def items(self):
        return self.to_json().items()

    def __getitem__(self, key):
        if isinstance(key, str):
            if key not in self.names:
                raise KeyError(key)
            return getattr(self, key)
        return (self.K_p, self.K_d, self.K_dK_i)[key]

    def __iter__(self):
        return iter((self.K_p, self.K_d, self.K_dK_i))

    def __len__(self) -> int:
        return 3

    def __str__(self) -> str:
        return (
            f"K_p = {self.K_p:.4g} N m, K_d = {self.K_d:.4g} N m s, "
            f"K_dK_i = {self.K_dK_i:.4g} N m/s"
        )


#: ``K_p`` (N m), ``K_d`` (N m s), ``K_d K_i`` (N m/s): seed 000 Tables 1 and 2.
SEED000_GAINS = BalancingGains(1e-3, 1.8e-3, 2e-5)
#: 1/s, default integral pole of :func:`tilt_pid_gains`: the seed-000 ratio K_d K_i / K_p
#: (2e-5 / 1e-3, seed 000 Tables 1-2); the slowest pole of the tilt loop (time constant 50 s).
TILT_INTEGRAL_RATE = SEED000_GAINS[2] / SEED000_GAINS[0]

#: ``K`` (N m), ``P`` (N m s), ``K_I`` (1/(N m s)) of seed 004 eq. 51. Seed 004 gives no
#: numbers; these match the seed-000 PID at small tilt (``q4 q_ep ~ theta / 2``):
#: ``K = 2 K_p``, ``P = K_d``, ``P K_I K / 2 = K_d K_i``.
LYAPUNOV_DEFAULT_GAINS = (
    2 * SEED000_GAINS[0],
    SEED000_GAINS[1],
    2 * SEED000_GAINS[2] / (SEED000_GAINS[1] * 2 * SEED000_GAINS[0]),
)

#: ``k_p`` (N m s) and the adaptation gain ``gamma`` as a stiffness (N m/rad) of the
#: Chesi et al. law. The paper's numbers are for another testbed; these match the seed-000
#: PID: ``k_p = K_d``, and near level the adaptive term acts as a tilt stiffness
#: ``gamma m^2 |g|^2``, set equal to ``K_p`` (so ``gamma = K_p / (m |g|)^2`` is computed from
#: the testbed's mass).
ADAPTIVE_DEFAULT_GAINS = (SEED000_GAINS[1], SEED000_GAINS[0])

#: Actuators a PID term can be assigned to.
ACTUATORS = ("sliders", "magnetorquers")

_Z_HAT = ca.DM([0.0, 0.0, 1.0])


def _numeric(fn):
    """Let a CasADi expression builder also take and return NumPy arrays."""

    @wraps(fn)
    def wrapper(*args, **kwargs):
        if any(isinstance(a, ca.SX | ca.MX) for a in args):
            return fn(*args, **kwargs)
        out = fn(*[ca.DM(np.asarray(a, float)) if _is_array(a) else a for a in args], **kwargs)
        if isinstance(out, tuple):
            return tuple(np.asarray(o, float).ravel() for o in out)
        return np.asarray(out, float).ravel()

    return wrapper


def _is_array(a) -> bool:
    return isinstance(a, np.ndarray | list | tuple | ca.DM | float | int)


def _perp(v, g_hat):
    """Component of ``v`` orthogonal to the unit ``g_hat`` (seed 004 eq. 25)."""
    return v - ca.dot(v, g_hat) * g_hat


def slider_matrix(axes, masses) -> np.ndarray:
    """``T`` with ``s = T M``: slider positions (m) giving the mass moment ``M`` (kg m).

    The sliders move the mass moment by ``M = sum_i m_i s_i u_i = A^T diag(m) s`` (seed 004
    eqs. 4-5; FORMATS.md), so ``T = (A^T diag(m))^-1`` with ``A`` the rail unit vectors as
    rows. Rails along any three independent axes work (seed 004 mounts them rotated 45 deg
    about z).
    """
    A = np.asarray(axes, dtype=float)
    m = np.asarray(masses, dtype=float).reshape(-1)
    if A.shape != (3, 3) or m.shape != (3,):
        raise InputError(f"slider axes {A.shape} and masses {m.shape}: expected (3, 3) and (3,)")
    if np.any(m <= 0):
        raise InputError(f"masses.mass {m.tolist()}: every sliding mass must be > 0 kg")
    B = A.T * m
    if abs(np.linalg.det(B)) < 1e-9 * np.prod(m):
        raise InputError(f"masses.axes {A.tolist()}: the three rails must span 3-D space")
    return np.linalg.inv(B)


@_numeric
def torque_to_sliders(tau, g_hat, gravity, axes, masses):
    """Slider displacements (m) that make the torque ``tau`` (N m, body) about the CR.

    ``M = g_hat x tau / |g|`` (seed 000 eq. 5, seed 004 eq. 13, written for the mass
    moment ``M`` instead of one combined mass), then ``s = T M`` (:func:`slider_matrix`).
    Exact for the part of ``tau`` orthogonal to gravity; gravity cannot make the rest.

    Parameters
    ----------
    tau : (3,) N m, body axes.
    g_hat : (3,) unit gravity direction, body axes.
    gravity : float, m/s^2.
    axes : (3, 3) rail unit vectors (rows); masses : (3,) kg.
    """
    M = ca.cross(g_hat, tau) / gravity  # seed 000 eq. 5, seed 004 eq. 13
    return ca.mtimes(ca.DM(slider_matrix(np.asarray(axes), np.asarray(masses))), M)


@_numeric
def slider_torque(s, g_body, axes, masses):
    """Torque (N m) of slider displacements ``s`` (m) in gravity ``g_body`` (m/s^2, body).

    ``sum_i m_i s_i u_i x g`` (seed 000 eq. 2, seed 004 eq. 12).
    """
    A = ca.DM(np.asarray(axes, dtype=float))
    m = ca.DM(np.asarray(masses, dtype=float).reshape(-1))
    M = ca.mtimes(A.T, m * s)
    return ca.cross(M, g_body)


@_numeric
def dipole_for_torque(tau, b_body):
    """Dipole (A m^2) whose torque ``d x b`` is ``tau`` (N m) less its part along ``b``.

    ``d = b_hat x tau / |b|`` (seed 000 eq. 7).
    """
    return ca.cross(b_body, tau) / ca.sumsqr(b_body)


@_numeric
def in_plane_pid(g_hat, w, integral, gains):
    """The three terms of the seed-000 PID (eq. 3), each in N m.

    Parameters
    ----------
    g_hat : (3,) unit gravity direction, body. w : (3,) rate, rad/s.
    integral : (3,) ``int g_hat x z_hat dt`` (s), body. gains : ``K_p, K_d, K_d K_i``.

    Returns
    -------
    tau_p, tau_i, tau_d : the proportional, integral and derivative torques.
    """
    e = ca.cross(g_hat, _Z_HAT)  # seed 000 eq. 3: error g_hat x z_hat
    tau_p = gains[0] * e
    tau_i = gains[2] * _perp(integral, g_hat)
    tau_d = -gains[1] * _perp(w, g_hat)
    return tau_p, tau_i, tau_d


@dataclass(frozen=True)
class PIDSplit:
    """Which actuator carries each term of the seed-000 PID.

    Each of ``proportional``, ``integral``, ``derivative`` is ``"sliders"`` or
    ``"magnetorquers"``. :data:`MECHANICAL` is seed 000 eq. 8, :data:`MIXED` eqs. 5 and 7.
    """

    proportional: str = "sliders"
    integral: str = "sliders"
    derivative: str = "sliders"

    def __post_init__(self) -> None:
        for term in ("proportional", "integral", "derivative"):
            v = getattr(self, term)
            if v not in ACTUATORS:
                raise InputError(f"PIDSplit {term}={v!r}: expected one of {', '.join(ACTUATORS)}")

    def carried_by(self, actuator: str) -> tuple[str, ...]:
        """The terms (``"proportional"``, ...) that ``actuator`` carries."""
        if actuator not in ACTUATORS:
            raise InputError(f"actuator {actuator!r}: expected one of {', '.join(ACTUATORS)}")
        return tuple(
            t for t in ("proportional", "integral", "derivative") if getattr(self, t) == actuator
        )

    @property
    def uses_magnetorquers(self) -> bool:
        return bool(self.carried_by("magnetorquers"))

    def torques(self, tau_p, tau_i, tau_d):
        """``(tau_sliders, tau_magnetorquers)``, the PID torque shared as assigned."""
        terms = {"proportional": tau_p, "integral": tau_i, "derivative": tau_d}
        zero = 0 * tau_p
        sl, mg = zero, zero
        for name, value in terms.items():
            if getattr(self, name) == "sliders":
                sl = sl + value
            else:
                mg = mg + value
        return sl, mg

    def commands(self, tau_p, tau_i, tau_d, *, g_hat, gravity, b_body, axes, masses):
        """The two actuator commands for the PID terms.

        Returns
        -------
        ds : (3,) slider displacements, m (seed 000 eq. 5 or 8, :func:`torque_to_sliders`).
        d : (3,) dipole, A m^2 (seed 000 eq. 7, :func:`dipole_for_torque`); zero when the
            magnetorquers carry nothing.
        """
        sl, mg = self.torques(tau_p, tau_i, tau_d)
        ds = torque_to_sliders(sl, g_hat, gravity, axes, masses)
        d = dipole_for_torque(mg, b_body) if self.uses_magnetorquers else 0 * mg
        return ds, d


#: Seed 000 eq. 8: all of P, I and D through the sliders.
MECHANICAL = PIDSplit("sliders", "sliders", "sliders")
#: Seed 000 eqs. 5 and 7: P and I through the sliders, D through the magnetorquers.
MIXED = PIDSplit("sliders", "sliders", "magnetorquers")


def field_in_body(field_lab, g_hat, q):
    """Cage field in body axes (T) as the controller knows it.

    A vertical field (seed 000: anti-parallel to gravity) needs only the accelerometer:
    ``b = -b_z g_hat``. Any other field is rotated with the measured attitude ``q``.
    """
    b = np.asarray(field_lab, dtype=float)
    if np.hypot(b[0], b[1]) <= 1e-12 * abs(b[2]):
        return -b[2] * g_hat

    return quat.rotate_inverse(q, ca.DM(b))


# ---------------------------------------------------------------------------- controllers


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
        e = ca.cross(g_hat, _Z_HAT)
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
        qep, wp, zp = _perp(qe, g_hat), _perp(w, g_hat), _perp(z, g_hat)  # eqs. 26, 28, 31
        tau = -K * q4 * qep - P * wp - P * KI * zp  # seed 004 eq. 51
        if full:
            tau = tau + _perp(ca.cross(w, ca.mtimes(J, w)), g_hat)  # seed 004 eq. 34
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
        tau = -mass * ca.cross(c, g_vec) - kp * _perp(w, g_hat)  # -Phi r_hat - k_p P_p w
        r_next = c + dt * gamma * mass * ca.cross(g_vec, w)  # r_hat' = gamma Phi^T w
        return tau, ca.SX.zeros(3), r_next, r_next

    return _build(
        model, "adaptive", law, np.zeros(3), gains, ("k_p", "k_theta"),
        uses_mag=False, sliders=sliders, magnetorquers=None, slider_start=slider_start,
        slider_zero=slider_zero, extra_law_names=("r_hat_x", "r_hat_y", "r_hat_z"),
    )  # fmt: skip


def default_split(testbed) -> str:
    """The seed-000 PID split a platform can run: the default of every balancing function.

    Parameters
    ----------
    testbed : Testbed or Model
        The platform.

    Returns
    -------
    str
        ``"mixed"`` (sliders P and I, magnetorquers D; seed 000 eqs. 5, 7, the law of its
        Tables 1-2) on a testbed with magnetorquers and a field to push against;
        ``"mechanical"`` (the sliders carry all three terms, seed 000 eq. 8), the only split
        a platform without magnetorquers or field can run, otherwise.

    Examples
    --------
    >>> import airbearing as ab
    >>> default_split(ab.load_testbed("seed000-tabletop"))
    'mixed'
    """
    tb = getattr(testbed, "testbed", testbed)
    magnetic = tb.magnetorquers is not None and tb.field is not None
    return "mixed" if magnetic else "mechanical"


#: Method name -> how to build it (``balancing_controller``).
METHODS = ("mechanical", "mixed", "lyapunov", "adaptive")


def balancing_controller(model, method: str, **options) -> Controller:
    """The balancing controller of ``method`` (:data:`METHODS`); options go to its builder.

    Parameters
    ----------
    model : Model
        A ``kind = "platform"``, dof 3 Model.
    method : {"mechanical", "mixed", "lyapunov", "adaptive"}
        Seed 000's PID with the sliders alone (eq. 8) or with the magnetorquers (eqs. 5
        and 7), the Lyapunov law, or the adaptive law.
    **options
        Keywords of the method's builder (:func:`pid_balancing_controller`,
        :func:`lyapunov_balancing_controller`, :func:`adaptive_balancing_controller`):
        gains, actuator blocks, slider positions (m).

    Returns
    -------
    Controller

    Raises
    ------
    InputError
        An unknown method.

    Examples
    --------
    >>> import airbearing as ab
    >>> controller = ab.balancing_controller(ab.build_model("seed000-tabletop"), "mixed")
    >>> controller.name, controller.gain_names  # N m, N m s, N m/s
    ('balance_mixed', ('K_p', 'K_d', 'K_dK_i'))
    >>> ab.balancing_controller(ab.build_model("seed000-tabletop"), "magic")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: method='magic': expected one of mechanical|mixed|lyapunov|adaptive
    """
    if method == "mechanical":
        return pid_balancing_controller(model, split=MECHANICAL, **options)
    if method == "mixed":
        return pid_balancing_controller(model, split=MIXED, **options)
    if method == "lyapunov":
        return lyapunov_balancing_controller(model, **options)
    if method == "adaptive":
        return adaptive_balancing_controller(model, **options)
    raise InputError(f"method={method!r}: expected one of {'|'.join(METHODS)}")


def tilt_pid_gains(
    testbed,
    *,
    frequency: float | None = None,
    damping: float = 0.7,
    integral_rate: float = TILT_INTEGRAL_RATE,
) -> BalancingGains:
    """PID gains ``(K_p, K_d, K_d K_i)`` placing the poles of the linearised tilt loop.

    Returns a :class:`BalancingGains`.

    About level, a tilt ``theta`` about a horizontal body axis obeys (seed 000 eq. 1 with
    eq. 3) ``J s^3 + K_d s^2 + (K_p + k_g) s + K_d K_i = 0``, with ``k_g = -m |g| r_z`` the
    gravity stiffness of the testbed's nominal offset (sliders at zero) and ``J`` the mean
    of ``J_xx`` and ``J_yy``. Matching ``J (s^2 + 2 zeta w s + w^2)(s + b)`` gives
    ``K_d = J (2 zeta w + b)``, ``K_p = J (w^2 + 2 zeta w b) - k_g``, ``K_d K_i = J w^2 b``.

    Parameters
    ----------
    frequency : float, optional
        rad/s, ``w``; default the larger of the pendulum frequency ``sqrt(k_g / J)`` and
        the seed-000 loop's ``sqrt(K_p / J)`` (seed 000 Tables 1-2).
    damping : float
        ``zeta`` (0.7, the usual choice; the seed-000 gains give about 0.16).
    integral_rate : float
        1/s, ``b``; default 0.02, the seed-000 ratio ``K_d K_i / K_p``.
    """
    J_cr = testbed.body.inertia_matrix
    J = 0.5 * (J_cr[0, 0] + J_cr[1, 1])
    k_g = -testbed.body.mass * testbed.gravity * testbed.body.cm_offset_vec[2]
    if frequency is None:
        frequency = math.sqrt(max(k_g, SEED000_GAINS[0]) / J)
    checks = (("frequency", frequency), ("damping", damping), ("integral_rate", integral_rate))
    for name, v in checks:
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"{name} {v}: expected a positive number")
    w, z, b = frequency, damping, integral_rate
    kp = J * (w**2 + 2 * z * w * b) - k_g
    if kp < 0:
        raise InputError(
            f"frequency {w} rad/s is below the pendulum frequency {math.sqrt(k_g / J):.3g} "
            "rad/s: the loop would need a negative K_p"
        )
    return BalancingGains(kp, J * (2 * z * w + b), J * w**2 * b)


def lyapunov_gains_from_pid(pid_gains, inertia=None) -> tuple[float, float, float]:
    """Seed 004 eq. 51 gains ``(K, P, K_I)`` equivalent to a seed-000 PID at small tilt.

    ``q4 q_ep ~ theta / 2`` gives ``K = 2 K_p``, ``P = K_d`` and ``P K_I K / 2 = K_d K_i``
    (the ``J w`` part of ``z`` adds ``P K_I J`` of damping, left as is).
    """
    kp, kd, kdki = (float(v) for v in pid_gains)
    return (2 * kp, kd, 2 * kdki / (kd * 2 * kp))
