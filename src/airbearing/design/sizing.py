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
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from airbearing.design.steering import check_skew
from airbearing.errors import InputError

__all__ = ["SizingResult", "size_cluster", "TABLE5_DEFAULTS"]

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

    def __repr__(self) -> str:
        return (
            f"SizingResult(torque={self.torque:.4g}, momentum={self.momentum:.4g}, "
            f"flywheel_inertia={self.flywheel_inertia:.4g}, flywheel_mass={self.flywheel_mass:.4g})"
        )

    def __str__(self) -> str:
        return (
            f"torque {self.torque * 1e3:.4g} mN m, momentum {self.momentum * 1e3:.4g} mN m s "
            f"per flywheel\nflywheel {self.flywheel_inertia * 1e3:.4g} g m^2, "
            f"{self.flywheel_mass * 1e3:.4g} g, {self.flywheel_thickness * 1e3:.3g} mm thick"
        )

    def to_json(self) -> dict:
        """JSON-ready: SI values under unit-suffixed keys (and the inputs)."""
        d = asdict(self)
        return {
            "torque_nm": d["torque"],
            "momentum_nms": d["momentum"],
            "flywheel_inertia_kgm2": d["flywheel_inertia"],
            "flywheel_mass_kg": d["flywheel_mass"],
            "flywheel_thickness_m": d["flywheel_thickness"],
            "inputs": {
                "angle_deg": math.degrees(d["angle"]),
                "time_s": d["time"],
                "inertia_kgm2": d["inertia"],
                "gimbal_rate_deg_s": math.degrees(d["gimbal_rate"]),
                "skew_deg": math.degrees(d["skew"]),
                "flywheel_speed_rpm": d["flywheel_speed"] * 60 / (2 * math.pi),
                "inner_radius_m": d["inner_radius"],
                "outer_radius_m": d["outer_radius"],
                "density_kgm3": d["density"],
            },
        }

    to_dict = to_json  # the earlier name


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
    >>> print(sizing)
    torque 1.728 mN m, momentum 0.8661 mN m s per flywheel
    flywheel 0.002068 g m^2, 14.11 g, 5.82 mm thick
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
    )
