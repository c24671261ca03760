"""Flywheel sizing of a 4-CMG pyramid from a manoeuvre requirement (seed 001 Sec. 3, eqs. 5-9).

From the manoeuvre (angle ``a`` in time ``t_a``) and the platform inertia ``J``:

* required torque, bang-bang half accelerating, half braking: ``N = J a / (t_a/2)^2``
  (seed 001 eq. 5);
* momentum per flywheel, all four gimbals turning together at the largest rate about
  the yaw axis: ``N = 4 delta_dot_max h0 cos(delta) sin(beta)`` at ``delta = 0``
  (seed 001 eqs. 6-7);
* flywheel inertia ``I_f = h0 / omega_f`` (seed 001 eq. 13);
* mass of a tube of radii ``z1 < z2``: ``m_f = 2 I_f / (z1^2 + z2^2)`` (seed 001 eq. 8);
* thickness ``L_f = m_f / (rho pi (z2^2 - z1^2))`` (seed 001 eq. 9).

The defaults are the inputs of seed 001 Table 5 (and Table 6 for the skew and the
flywheel speed), so ``size_cluster(np.deg2rad(30), 2, 0.0033)`` gives Table 5.

Feasibility. Eq. 7 sizes ``h0`` for the torque at ``delta = 0``, but the gimbals turn
while the platform accelerates: at the largest rate for the accelerating half
``t_a / 2`` they reach ``delta_r = delta_dot_max t_a / 2``, and the cluster's momentum
about the yaw axis is then ``4 h0 sin(beta) sin(delta_r)`` (seed 001 eq. 12, third row,
with ``delta_1 = .. = delta_4``; eq. 7 is its time derivative). The bang-bang profile of
eq. 5 (Fig. 9) needs the body's peak momentum ``J w_peak``, ``w_peak = 2 a / t_a``, at
that instant. With ``h0`` from eq. 7 the share the cluster holds is ``sin(x) / x``,
``x = delta_dot_max t_a / 2`` (rad): 93.9 % for Table 5's 35 deg/s over 1 s, so the
Table 5 cluster completes the 30 deg in 2 s only with a faster gimbal rate (37.65 deg/s)
or larger flywheels (0.9224 mN m s).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from airbearing.design.steering import check_skew
from airbearing.errors import InputError

__all__ = ["SizingResult", "size_cluster", "TABLE5_DEFAULTS", "ROUND_TRIP_DIGITS"]

#: Significant digits of the inputs echoed in degrees and rpm: the conversion from radians
#: and rad/s and back leaves round-off (30 deg -> 29.999999999999996); 12 digits drop it.
ROUND_TRIP_DIGITS = 12

#: Seed 001 Table 5 (gimbal rate, radii, density) and Table 6 (skew, flywheel speed), SI.
TABLE5_DEFAULTS = {
    "gimbal_rate": math.radians(35.0),  # rad/s, Table 5: 35 deg/s
    "skew": math.radians(54.73),  # rad, Table 6
    "flywheel_speed": 4000.0 * 2 * math.pi / 60,  # rad/s, Table 6: 4000 rpm
    "inner_radius": 0.002,  # m, Table 5: z1 = 2 mm
    "outer_radius": 0.017,  # m, Table 5: z2 = 17 mm
    "density": 2710.0,  # kg/m^3, Table 5: 2.71 g/cm^3 (aluminium)
}


@dataclass(frozen=True)
class SizingResult:
    """Inputs and results of :func:`size_cluster`, SI units.

    Attributes
    ----------
    angle : float
        Manoeuvre angle, rad.
    time : float
        Manoeuvre time, s.
    inertia : float
        Platform inertia about the manoeuvre axis, kg m^2.
    gimbal_rate, skew, flywheel_speed : float
        rad/s, rad, rad/s.
    inner_radius, outer_radius, density : float
        m, m, kg/m^3.
    torque : float
        Required torque ``N_req``, N m (eq. 5).
    momentum : float
        Momentum per flywheel ``h0``, N m s (eq. 7).
    flywheel_inertia : float
        ``I_f``, kg m^2 (eq. 13).
    flywheel_mass : float
        ``m_f``, kg (eq. 8).
    flywheel_thickness : float
        ``L_f``, m (eq. 9).
    peak_body_rate : float
        ``w_peak = 2 a / t_a``, rad/s: the body rate at ``t_a / 2`` (eq. 5, Fig. 9).
    momentum_needed : float
        ``J w_peak``, N m s: the body's momentum then, which the cluster must hold.
    gimbal_angle_reached : float
        ``delta_dot_max t_a / 2``, rad: where the gimbals are then at the largest rate.
    cluster_momentum : float
        ``4 h0 sin(beta) sin(delta)``, N m s, at that angle (eq. 12; at most the envelope,
        ``delta`` = 90 deg).
    momentum_fraction : float
        ``cluster_momentum / momentum_needed``, -; below 1 the manoeuvre takes longer.
    gimbal_rate_needed : float or None
        rad/s, the gimbal rate at which the cluster holds ``momentum_needed`` at
        ``t_a / 2`` (None: more than the cluster's envelope ``4 h0 sin(beta)``, no rate).
    momentum_per_flywheel_needed : float
        N m s, the ``h0`` that holds ``momentum_needed`` at ``t_a / 2`` at ``gimbal_rate``.
    warnings : list of str
        The shortfall in words (empty when the cluster holds what is needed).

    Examples
    --------
    Seed 001 Table 5: a 30 deg yaw manoeuvre in 2 s of a 0.0033 kg m^2 platform:

    >>> import math
    >>> import airbearing as ab
    >>> sizing = ab.size_cluster(math.radians(30.0), 2.0, 0.0033)
    >>> sizing
    SizingResult(torque=0.001728, momentum=0.0008661, flywheel_inertia=2.068e-06,
                 flywheel_mass=0.01411)
    >>> round(sizing.to_json()["torque_nm"] * 1e3, 3)  # mN m
    1.728
    """

    angle: float
    time: float
    inertia: float
    gimbal_rate: float
    skew: float
    flywheel_speed: float
    inner_radius: float
    outer_radius: float
    density: float
    torque: float
    momentum: float
    flywheel_inertia: float
    flywheel_mass: float
    flywheel_thickness: float
    peak_body_rate: float = math.nan
    momentum_needed: float = math.nan
    gimbal_angle_reached: float = math.nan
    cluster_momentum: float = math.nan
    momentum_fraction: float = math.nan
    gimbal_rate_needed: float | None = None
    momentum_per_flywheel_needed: float = math.nan
    warnings: tuple = ()

    def __repr__(self) -> str:
        return (
            f"SizingResult(torque={self.torque:.4g}, momentum={self.momentum:.4g}, "
            f"flywheel_inertia={self.flywheel_inertia:.4g}, flywheel_mass={self.flywheel_mass:.4g})"
        )

    def __str__(self) -> str:
        return "\n".join([
            f"torque {self.torque * 1e3:.4g} mN m, momentum {self.momentum * 1e3:.4g} mN m s "
            f"per flywheel",
            f"flywheel {self.flywheel_inertia * 1e3:.4g} g m^2, "
            f"{self.flywheel_mass * 1e3:.4g} g, {self.flywheel_thickness * 1e3:.3g} mm thick",
            f"at t/2 the gimbals are at {math.degrees(self.gimbal_angle_reached):.4g} deg and "
            f"the cluster holds {self.cluster_momentum * 1e3:.4g} mN m s, "
            f"{100 * self.momentum_fraction:.1f} % of the {self.momentum_needed * 1e3:.4g} "
            "mN m s needed",
            *(f"warning: {w}" for w in self.warnings),
        ])  # fmt: skip

    def to_json(self) -> dict:
        """JSON-ready: SI values under unit-suffixed keys (and the inputs).

        Returns
        -------
        dict
            ``torque_nm``, ``momentum_nms``, ``flywheel_inertia_kgm2``, ``flywheel_mass_kg``,
            ``flywheel_thickness_m``, ``inputs`` (deg, s, kg m^2, deg/s, rpm, m, kg/m^3),
            the momentum check's keys and ``warnings``.
        """
        d = asdict(self)

        def echo(x):  # a value in deg or rpm without the round trip's round-off
            return float(f"{x:.{ROUND_TRIP_DIGITS}g}")

        rate = self.gimbal_rate_needed
        return {
            "torque_nm": d["torque"],
            "momentum_nms": d["momentum"],
            "flywheel_inertia_kgm2": d["flywheel_inertia"],
            "flywheel_mass_kg": d["flywheel_mass"],
            "flywheel_thickness_m": d["flywheel_thickness"],
            "inputs": {
                "angle_deg": echo(math.degrees(d["angle"])),
                "time_s": d["time"],
                "inertia_kgm2": d["inertia"],
                "gimbal_rate_deg_s": echo(math.degrees(d["gimbal_rate"])),
                "skew_deg": echo(math.degrees(d["skew"])),
                "flywheel_speed_rpm": echo(d["flywheel_speed"] * 60 / (2 * math.pi)),
                "inner_radius_m": d["inner_radius"],
                "outer_radius_m": d["outer_radius"],
                "density_kgm3": d["density"],
            },
            "peak_body_rate_deg_s": echo(math.degrees(self.peak_body_rate)),
            "momentum_needed_nms": self.momentum_needed,
            "gimbal_angle_reached_deg": echo(math.degrees(self.gimbal_angle_reached)),
            "cluster_momentum_nms": self.cluster_momentum,
            "momentum_fraction": self.momentum_fraction,
            "gimbal_rate_needed_deg_s": None if rate is None else math.degrees(rate),
            "momentum_per_flywheel_needed_nms": self.momentum_per_flywheel_needed,
            "warnings": list(self.warnings),
        }


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} {value!r}: expected a positive number") from None
    if not math.isfinite(v) or v <= 0:
        raise InputError(f"{name} {v}: expected a positive number")
    return v


def size_cluster(
    angle: float,
    time: float,
    inertia: float,
    *,
    gimbal_rate: float = TABLE5_DEFAULTS["gimbal_rate"],
    skew: float = TABLE5_DEFAULTS["skew"],
    flywheel_speed: float = TABLE5_DEFAULTS["flywheel_speed"],
    inner_radius: float = TABLE5_DEFAULTS["inner_radius"],
    outer_radius: float = TABLE5_DEFAULTS["outer_radius"],
    density: float = TABLE5_DEFAULTS["density"],
) -> SizingResult:
    """Size the flywheels of a 4-CMG pyramid for a rest-to-rest manoeuvre (seed 001 eqs. 5-9).

    Parameters
    ----------
    angle : float
        Manoeuvre angle ``a``, rad (> 0).
    time : float
        Time to complete it ``t_a``, s (> 0).
    inertia : float
        Platform inertia about the manoeuvre axis ``J``, kg m^2 (> 0).
    gimbal_rate : float
        Largest gimbal rate, rad/s (> 0); Table 5: 35 deg/s.
    skew : float
        Pyramid skew ``beta``, rad, strictly between 0 and pi/2; Table 6: 54.73 deg.
    flywheel_speed : float
        ``omega_f``, rad/s (> 0); Table 6: 4000 rpm.
    inner_radius, outer_radius : float
        ``z1 < z2``, m; Table 5: 2 mm and 17 mm.
    density : float
        Flywheel material, kg/m^3 (> 0); Table 5: 2710 (aluminium).

    Returns
    -------
    SizingResult

    Raises
    ------
    InputError
        A value that is not a positive finite number (named by its parameter), or radii
        out of order.

    Examples
    --------
    Seed 001 Table 5: a 30 deg yaw manoeuvre in 2 s of a 0.0033 kg m^2 platform.

    >>> import math
    >>> import airbearing as ab
    >>> sizing = ab.size_cluster(math.radians(30.0), 2.0, 0.0033)
    >>> print(sizing)  # doctest: +NORMALIZE_WHITESPACE
    torque 1.728 mN m, momentum 0.8661 mN m s per flywheel
    flywheel 0.002068 g m^2, 14.11 g, 5.82 mm thick
    at t/2 the gimbals are at 35 deg and the cluster holds 1.622 mN m s, 93.9 % of the
    1.728 mN m s needed
    warning: at 35 deg/s the gimbals reach 35 deg at t/2 = 1 s, where the cluster holds
    1.622 mN m s of the 1.728 mN m s the body needs then (93.9 %; eq. 7 sizes h0 for the
    torque at 0 deg): the manoeuvre takes longer than 2 s unless the gimbals turn at
    37.65 deg/s or each flywheel stores 0.9224 mN m s
    >>> round(sizing.to_json()["flywheel_mass_kg"], 4)
    0.0141
    >>> ab.size_cluster(0.0, 2.0, 0.0033)
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: angle 0.0: expected a positive number
    """
    a = _positive("angle", angle)
    t = _positive("time", time)
    J = _positive("inertia", inertia)
    rate = _positive("gimbal_rate", gimbal_rate)
    w_f = _positive("flywheel_speed", flywheel_speed)
    rho = _positive("density", density)
    z2 = _positive("outer_radius", outer_radius)
    try:
        z1 = float(inner_radius)
    except (TypeError, ValueError):
        raise InputError(f"inner_radius {inner_radius!r}: expected a number >= 0 in m") from None
    if not (math.isfinite(z1) and 0 <= z1 < z2):
        raise InputError(
            f"inner_radius {z1} m, outer_radius {z2} m: expected 0 <= inner < outer radius"
        )
    beta = check_skew(skew)

    torque = J * a / (t / 2) ** 2  # seed 001 eq. 5
    h0 = torque / (4 * rate * math.cos(0.0) * math.sin(beta))  # seed 001 eq. 7 at delta = 0
    I_f = h0 / w_f  # seed 001 eq. 13
    m_f = 2 * I_f / (z1**2 + z2**2)  # seed 001 eq. 8
    L_f = m_f / (rho * math.pi * (z2**2 - z1**2))  # seed 001 eq. 9
    feasible = _feasibility(a, t, J, rate, beta, h0)
    return SizingResult(
        angle=a,
        time=t,
        inertia=J,
        gimbal_rate=rate,
        skew=beta,
        flywheel_speed=w_f,
        inner_radius=z1,
        outer_radius=z2,
        density=rho,
        torque=torque,
        momentum=h0,
        flywheel_inertia=I_f,
        flywheel_mass=m_f,
        flywheel_thickness=L_f,
        **feasible,
    )


def _feasibility(a: float, t: float, J: float, rate: float, beta: float, h0: float) -> dict:
    """What the sized cluster holds at ``t / 2`` against what the manoeuvre needs then.

    Bang-bang (seed 001 eq. 5, Fig. 9): peak body rate ``w = 2 a / t`` at ``t / 2``, body
    momentum ``J w``. Gimbals together at ``rate`` from 0 reach ``delta = rate t / 2``;
    the cluster's yaw momentum is ``4 h0 sin(beta) sin(delta)`` (seed 001 eq. 12, third
    row), at most the envelope ``4 h0 sin(beta)`` (delta = 90 deg).
    """
    w_peak = 2 * a / t  # rad/s, eq. 5's profile at t / 2
    needed = J * w_peak  # N m s
    reached = rate * t / 2  # rad
    along = 4 * math.sin(beta)  # the envelope along yaw, per h0 (eq. 12, delta = 90 deg)
    held = h0 * along * math.sin(min(reached, math.pi / 2))  # seed 001 eq. 12
    ratio = needed / (h0 * along)
    rate_needed = None if ratio > 1 else 2 * math.asin(ratio) / t
    h0_needed = needed / (along * math.sin(min(reached, math.pi / 2)))
    fraction = held / needed
    warnings = []
    if fraction < 1:
        how = (
            f"the gimbals turn at {math.degrees(rate_needed):.4g} deg/s or "
            if rate_needed is not None
            else "(no gimbal rate is enough: the cluster's envelope along yaw, "
            f"{h0 * along * 1e3:.4g} mN m s, is below it) "
        )
        warnings.append(
            f"at {math.degrees(rate):.4g} deg/s the gimbals reach {math.degrees(reached):.4g} "
            f"deg at t/2 = {t / 2:.4g} s, where the cluster holds {held * 1e3:.4g} mN m s of "
            f"the {needed * 1e3:.4g} mN m s the body needs then ({100 * fraction:.1f} %; "
            f"eq. 7 sizes h0 for the torque at 0 deg): the manoeuvre takes longer than "
            f"{t:.4g} s unless {how}each flywheel stores {h0_needed * 1e3:.4g} mN m s"
        )
    return {
        "peak_body_rate": w_peak,
        "momentum_needed": needed,
        "gimbal_angle_reached": reached,
        "cluster_momentum": held,
        "momentum_fraction": fraction,
        "gimbal_rate_needed": rate_needed,
        "momentum_per_flywheel_needed": h0_needed,
        "warnings": tuple(warnings),
    }
