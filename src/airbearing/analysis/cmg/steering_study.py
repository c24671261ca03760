"""Steering-law studies on CMG platforms: slews, rate limiting and the internal singularity.

Three studies, each returning plain numbers so tests and reports use the same code:

* :func:`momentum_tracking` / :func:`internal_singularity_case`: the cluster alone
  (gimbal kinematics ``delta' = delta_dot``, held over each sample) tracking a momentum
  ramp. The benchmark case is the pyramid with ``beta = 53.13 deg`` starting at
  ``delta = 0`` with a momentum demand along body x: on the symmetric path
  ``delta = (-theta, 0, theta, 0)`` the cluster momentum is ``2 cos(beta) sin(theta) x``
  (seed 001 eq. 12), which ends at the elliptic internal singularity
  ``delta = (-90, 0, 90, 0) deg``, ``H = 2 cos(beta) h0 x = 1.2 h0 x``, the well-known
  trap of Moore-Penrose and SR steering for a demand along the singular direction
  (Wie, Bailey & Heiberg, JGCD 24(5), 2001; Wie, JGCD 28(5), 2005). The dithered laws
  (``gsr``, ``sda``) leave it; ``mp`` and ``sr`` stay.
* :func:`compare_slews`: closed-loop rest-to-rest slews (seed 001's loop, eqs. 3, 11,
  16, 19-21, eq. 4) with each law on a 1-DoF or 3-DoF platform: pointing error, peak
  gimbal rate, time near singularity, time to escape, torque error.
* :func:`rate_limit_comparison`: seed 001 eq. 4 (scale all rates) against per-gimbal
  clipping.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import pandas as pd

from airbearing import quaternion as quat
from airbearing.analysis.cmg.singularity import (
    measure,
    singular_states,
    singularity_summary,
)
from airbearing.analysis.simulation.scenarios import slew
from airbearing.design.steering import (
    STEERING_LAWS,
    check_skew,
    saturate_rates,
    steering_function,
)
from airbearing.errors import InputError
from airbearing.io.output import to_jsonable
from airbearing.io.testbed import Body, Testbed, load_testbed
from airbearing.models.cmg import jacobian_normalised, momentum_normalised

__all__ = [
    "BENCHMARK_SKEW_DEG",
    "NEAR_SINGULAR",
    "SEED001_REFERENCE_INERTIA",
    "SteeringRun",
    "momentum_tracking",
    "internal_singularity_case",
    "null_motion_run",
    "cmg_3dof_testbed",
    "slew_metrics",
    "compare_slews",
    "rate_limit_comparison",
    "rotation_error_deg",
    "null_motion_cases",
]

#: deg, the skew of the literature's benchmark pyramid (Wie 2005): cos(beta) = 0.6.
BENCHMARK_SKEW_DEG = 53.13
#: kg m^2, seed 001 Table 5: the reference cuboid, the same inertia about every axis.
SEED001_REFERENCE_INERTIA = 0.0033
#: normalised m below which a run counts as "near a singularity".
NEAR_SINGULAR = 0.2

_d, _b = ca.SX.sym("d", 4), ca.SX.sym("b")
_H_FN = ca.Function("H", [_d, _b], [momentum_normalised(_d, _b)])  # seed 001 eq. 12
_A_FN = ca.Function("A", [_d, _b], [jacobian_normalised(_d, _b)])  # seed 001 eq. 15


def _H_many(delta: np.ndarray, beta: float) -> np.ndarray:
    """Normalised momentum for each row of ``delta`` (N, 4) -> (N, 3)."""
    return np.asarray(_H_FN.map(delta.shape[0])(delta.T, beta)).T


def _A_many(delta: np.ndarray, beta: float) -> np.ndarray:
    """Normalised Jacobians for each row of ``delta`` (N, 4) -> (N, 3, 4)."""
    out = np.asarray(_A_FN.map(delta.shape[0])(delta.T, beta))  # 3 x 4N
    return out.reshape(3, delta.shape[0], 4).transpose(1, 0, 2)


@dataclass(frozen=True)
class SteeringRun:
    """A momentum-tracking run of the cluster alone (normalised: momentum in units of h0).

    Attributes
    ----------
    law : str
        Steering law.
    t : ndarray (N,)
        Sample times, s.
    delta : ndarray (N + 1, 4)
        Gimbal angles, rad, at ``t_0 .. t_N``.
    H, H_ref : ndarray (N + 1, 3)
        Cluster momentum and its reference (h0).
    h_cmd, h_out : ndarray (N, 3)
        Commanded and delivered momentum rate ``A delta_dot`` (h0/s).
    delta_dot : ndarray (N, 4)
        Gimbal rates after the rate limit, rad/s.
    m : ndarray (N + 1,)
        Singularity measure.
    tolerance : float
        Momentum error (h0) within which the manoeuvre counts as completed.
    info : dict
        The run's settings (skew, direction, ramp, limit ...), for the record.

    Examples
    --------
    The singularity-robust law tracking a 1 h0 ramp along body x for 8 s:

    >>> import airbearing as ab
    >>> run = ab.momentum_tracking("sr", h_final=1.0, duration=8.0)
    >>> print(run)
    sr: completed in 5 s, peak gimbal rate 17 deg/s
    >>> run.summary()["completed"], run.to_json()["law"], run.to_pandas().shape
    (True, 'sr', (160, 12))
    """

    law: str
    t: np.ndarray = field(repr=False)
    delta: np.ndarray = field(repr=False)
    H: np.ndarray = field(repr=False)
    H_ref: np.ndarray = field(repr=False)
    h_cmd: np.ndarray = field(repr=False)
    h_out: np.ndarray = field(repr=False)
    delta_dot: np.ndarray = field(repr=False)
    m: np.ndarray = field(repr=False)
    tolerance: float = 0.05
    info: dict = field(default_factory=dict, repr=False)

    def __str__(self) -> str:
        s = self.summary()
        done = (
            f"completed in {s['completion_time_s']:.3g} s"
            if s["completed"]
            else f"not completed (final momentum error {s['final_momentum_error_h0']:.3g} h0"
            + (
                ", the reference still moves at the end of the run)"
                if s["reference_moving"]
                else ")"
            )
        )
        return f"{self.law}: {done}, peak gimbal rate {s['peak_gimbal_rate_deg_s']:.3g} deg/s"

    def to_json(self) -> dict:
        """:meth:`summary` with infinite values as None (JSON null).

        Returns
        -------
        dict
        """
        return to_jsonable(self.summary())

    def to_pandas(self):
        """The run as a table.

        Returns
        -------
        pandas.DataFrame
            ``t`` (s), gimbal angles ``delta1..4`` (rad), momentum ``Hx Hy Hz`` and
            reference ``Hx_ref ..`` (h0), singularity measure ``m``.
        """
        n = len(self.t)
        cols = {"t": self.t}
        cols |= {f"delta{i + 1}": self.delta[:n, i] for i in range(4)}
        cols |= {f"H{a}": self.H[:n, i] for i, a in enumerate("xyz")}
        cols |= {f"H{a}_ref": self.H_ref[:n, i] for i, a in enumerate("xyz")}
        cols["m"] = self.m[:n]
        return pd.DataFrame(cols)

    def summary(self) -> dict:
        """Tracking error, peak gimbal rate, time near singularity, time to escape.

        Returns
        -------
        dict
            ``law``, ``final_momentum_error_h0``, ``max_torque_error_h0_s``,
            ``final_torque_error_h0_s``, ``peak_gimbal_rate_deg_s``, ``completed``,
            ``completion_time_s`` (inf when not completed), ``final_Hx_h0``,
            ``reference_moving`` and the singularity keys (``min_m``, ``time_near_s``,
            ``time_to_escape_s``, ``escaped``).
        """
        err = np.linalg.norm(self.H - self.H_ref, axis=1)
        terr = np.linalg.norm(self.h_out - self.h_cmd, axis=1)
        tt = np.append(self.t, self.t[-1] + (self.t[1] - self.t[0]))
        # completion: the first time after which the reference has reached its final value
        # and the error stays within the tolerance; a run that ends while the reference
        # still moves has not completed the manoeuvre, however well it tracks
        moving = np.nonzero(np.linalg.norm(np.diff(self.H_ref, axis=0), axis=1) > 1e-12)[0]
        ref_final = int(moving[-1]) + 1 if moving.size else 0
        ref_done = ref_final < len(err) - 1 or not moving.size
        inside = err < self.tolerance
        inside[:ref_final] = False
        done = None
        if inside[-1] and ref_done:
            last_out = np.nonzero(~inside)[0]
            done = float(tt[last_out[-1] + 1]) if last_out.size else float(tt[0])
        s = singularity_summary(tt, self.m, threshold=NEAR_SINGULAR)
        return {
            "law": self.law,
            "final_momentum_error_h0": float(err[-1]),
            "max_torque_error_h0_s": float(terr.max()),
            "final_torque_error_h0_s": float(terr[-1]),
            "peak_gimbal_rate_deg_s": float(np.rad2deg(np.abs(self.delta_dot).max())),
            "completed": done is not None,
            "completion_time_s": done if done is not None else float("inf"),
            "final_Hx_h0": float(self.H[-1, 0]),
            "reference_moving": not ref_done,
            **s,
        }


def momentum_tracking(
    law: str,
    *,
    skew_deg: float = BENCHMARK_SKEW_DEG,
    direction=(1.0, 0.0, 0.0),
    h_final: float = 2.0,
    ramp_rate: float = 0.2,
    gain: float = 1.0,
    duration: float = 30.0,
    dt: float = 0.05,
    delta0=(0.0, 0.0, 0.0, 0.0),
    max_gimbal_rate_deg: float = 64.498,
    rate_limit_mode: str = "scale",
    steering_options: dict | None = None,
    tolerance: float = 0.05,
) -> SteeringRun:
    """The cluster alone tracking a momentum ramp, one compiled CasADi ``mapaccum``.

    Each sample: ``H_ref`` ramps along ``direction`` at ``ramp_rate`` (h0/s) up to
    ``h_final`` (h0); the demand ``h_cmd = H_ref' + gain (H_ref - H)`` goes through the
    steering law (normalised Jacobian, seed 001 eqs. 14-16) and the rate limit (seed
    001 eq. 4, or clipping); the rates are held over ``dt`` so ``delta`` advances exactly.

    Parameters
    ----------
    law : str
        Steering law name (:data:`airbearing.design.steering.STEERING_LAWS`).
    skew_deg : float
        Pyramid skew, deg (0 < skew < 90).
    direction : 3 floats
        Direction of the momentum demand, body axes.
    h_final : float
        Final momentum, h0 (> 0).
    ramp_rate : float
        Ramp slope, h0/s (> 0).
    gain : float
        Momentum feedback, 1/s (>= 0).
    duration, dt : float
        Run length and sample time, s.
    delta0 : 4 floats
        Initial gimbal angles, rad.
    max_gimbal_rate_deg : float
        Rate limit, deg/s (seed 001 Table 6: 64.498).
    rate_limit_mode : {"scale", "clip"}
        Seed 001 eq. 4 or per-gimbal clipping.
    steering_options : dict, optional
        Options of the law.
    tolerance : float
        Momentum error (h0) within which the manoeuvre counts as completed.

    Returns
    -------
    SteeringRun

    Raises
    ------
    InputError
        A skew outside (0, 90) deg, a non-positive final momentum, ramp or sample time, a
        duration shorter than one sample, a negative gain or rate limit, a zero direction,
        an unknown law.

    Examples
    --------
    >>> import airbearing as ab
    >>> run = ab.momentum_tracking("mp", direction=(0.0, 0.0, 1.0), h_final=1.0, duration=8.0)
    >>> run.law, run.H.shape  # momentum in h0
    ('mp', (161, 3))
    """
    beta = check_skew(np.deg2rad(skew_deg), "skew_deg")
    for name, v, lo in (("h_final", h_final, 0), ("ramp_rate", ramp_rate, 0), ("dt", dt, 0)):
        if not np.isfinite(v) or v <= lo:
            raise InputError(f"{name} = {v}: expected a positive number")
    if not np.isfinite(duration) or duration < dt:
        raise InputError(f"duration = {duration} s: expected at least one sample ({dt} s)")
    if gain < 0 or max_gimbal_rate_deg <= 0:
        raise InputError("gain must be >= 0 (1/s) and max_gimbal_rate_deg > 0 (deg/s)")
    e = np.asarray(direction, float)
    if e.shape != (3,) or np.linalg.norm(e) == 0:
        raise InputError(f"direction {list(direction)}: expected a non-zero 3-vector")
    e = e / np.linalg.norm(e)
    steer = steering_function(law, **(steering_options or {}))
    limit = np.deg2rad(max_gimbal_rate_deg)

    d = ca.SX.sym("delta", 4)
    t = ca.SX.sym("t")
    p = ca.SX.sym("p", 3)  # ramp_rate, h_final, gain
    ev = ca.DM(e)
    H = momentum_normalised(d, beta)  # seed 001 eq. 12 (per h0)
    A = jacobian_normalised(d, beta)  # seed 001 eqs. 14-15
    ramping = t * p[0] < p[1]
    H_ref = ca.fmin(t * p[0], p[1]) * ev
    h_cmd = ca.if_else(ramping, p[0], 0) * ev + p[2] * (H_ref - H)
    dd = saturate_rates(steer(A, h_cmd, d, t), limit, rate_limit_mode)
    d_next = d + dt * dd
    step = ca.Function(
        "track_step", [d, t, p], [d_next, ca.vertcat(H, H_ref, h_cmd, ca.mtimes(A, dd), dd)]
    )
    n = int(round(duration / dt))
    F = step.mapaccum("track", n, [0], [0])
    tt = np.arange(n) * dt
    D, R = F(np.asarray(delta0, float), tt[None, :], np.array([ramp_rate, h_final, gain]))
    D, R = np.asarray(D).T, np.asarray(R).T
    delta = np.vstack([np.asarray(delta0, float), D])
    Hs = _H_many(delta, beta)
    Href = np.minimum((np.append(tt, n * dt) * ramp_rate)[:, None], h_final) * e
    return SteeringRun(
        law=law,
        t=tt,
        delta=delta,
        H=Hs,
        H_ref=Href,
        h_cmd=R[:, 6:9],
        h_out=R[:, 9:12],
        delta_dot=R[:, 12:16],
        m=measure(delta, beta),
        tolerance=tolerance,
        info={"skew_deg": skew_deg, "rate_limit_mode": rate_limit_mode, "dt": dt},
    )


def internal_singularity_case(law: str, *, duration: float = 30.0, **options) -> SteeringRun:
    """The benchmark manoeuvre through the elliptic internal singularity (see module doc).

    ``beta = 53.13 deg``, ``delta(0) = 0``, momentum ramp along x at 0.2 h0/s to
    2.0 h0 (inside the envelope, whose x extent is ``2 + 2 cos(beta) = 3.2 h0``), seed
    001's rate limit. Moore-Penrose stalls at ``2 cos(beta) = 1.2 h0``.
    """
    return momentum_tracking(law, duration=duration, **options)


def null_motion_run(
    delta0,
    *,
    skew_deg: float = BENCHMARK_SKEW_DEG,
    law: str = "mp",
    gain: float = 1.0,
    hold_gain: float = 1.0,
    duration: float = 10.0,
    dt: float = 0.05,
    max_gimbal_rate_deg: float = 64.498,
) -> dict:
    """Null motion alone: the cluster holds its momentum while the gimbals move away from
    a singular set (gradient of ``m`` projected on the null space of ``A``).

    The demand is ``hold_gain (H(delta0) - H)`` (zero but for the drift of the
    discrete step); returns ``t`` (s), ``delta`` (rad), ``m`` and ``drift_h0``
    (``|H - H(delta0)|``, h0).
    """
    beta = check_skew(np.deg2rad(skew_deg), "skew_deg")
    if gain <= 0:
        raise InputError(f"null-motion gain {gain}: expected > 0")
    steer = steering_function(law, null_motion_gain=gain, skew=beta)
    d, t = ca.SX.sym("delta", 4), ca.SX.sym("t")
    d0 = np.asarray(delta0, float)
    H0 = _H_FN(d0, beta)
    H = momentum_normalised(d, beta)  # seed 001 eq. 12
    A = jacobian_normalised(d, beta)  # seed 001 eq. 15
    dd = saturate_rates(steer(A, hold_gain * (H0 - H), d, t), np.deg2rad(max_gimbal_rate_deg))
    step = ca.Function("null_step", [d, t], [d + dt * dd])
    n = int(round(duration / dt))
    D = np.asarray(step.mapaccum("null_motion", n)(d0, (np.arange(n) * dt)[None, :])).T
    delta = np.vstack([d0, D])
    return {
        "t": np.arange(n + 1) * dt,
        "delta": delta,
        "m": measure(delta, beta),
        "drift_h0": np.linalg.norm(_H_many(delta, beta) - np.asarray(H0).ravel(), axis=1),
    }


def null_motion_cases() -> list[tuple[str, np.ndarray]]:
    """Start states 2 deg off a hyperbolic and off the elliptic singular state (beta 53.13)."""
    beta = np.deg2rad(BENCHMARK_SKEW_DEG)
    el, az = np.deg2rad(-18.0), np.deg2rad(-54.0)
    u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    d_h, _ = singular_states(u, beta, (1, 1, -1, -1))
    off = np.deg2rad([2.0, -1.0, 1.0, 0.5])
    return [
        ("near hyperbolic", d_h + off),
        ("near elliptic", np.deg2rad([-90.0, 0.0, 90.0, 0.0]) + off),
    ]


# ---------------------------------------------------------------- platform slews


def cmg_3dof_testbed(
    *,
    inertia=SEED001_REFERENCE_INERTIA,
    skew_deg: float | None = None,
    base: Testbed | None = None,
) -> Testbed:
    """The seed-001 cluster on a 3-DoF (spherical) bearing.

    ``inertia``: a number (the same about every axis, seed 001 Table 5's reference
    cuboid, 0.0033 kg m^2) or a 3x3 matrix (kg m^2). ``skew_deg`` replaces the skew.
    """
    tb = load_testbed("cmg-yaw") if base is None else base
    J = np.asarray(inertia, dtype=float)
    J = np.eye(3) * float(J) if J.ndim == 0 else J
    body = Body(dof=3, mass=tb.body.mass, inertia=tuple(map(tuple, J.tolist())))
    changes: dict = {"body": body, "name": f"{tb.name}-3dof"}
    if skew_deg is not None:
        changes["cmg"] = type(tb.cmg)(
            skew=check_skew(np.deg2rad(skew_deg), "skew_deg"),
            flywheel_inertia=tb.cmg.flywheel_inertia,
            flywheel_speed=tb.cmg.flywheel_speed,
            max_gimbal_rate=tb.cmg.max_gimbal_rate,
            gimbal_angles=tb.cmg.gimbal_angles,
        )
    return tb.replace(**changes)


def rotation_error_deg(q_ref, q) -> np.ndarray:
    """deg, angle of the rotation from ``q_ref`` to ``q`` (each row, scalar-first)."""
    err = quat.qmul(quat.qconj(quat.normalize(q_ref)), q)
    return np.rad2deg(2 * np.arccos(np.clip(np.abs(err[..., 0]), 0.0, 1.0)))


def slew_metrics(result, *, settle_deg: float = 1.0) -> dict:
    """Pointing error, peak gimbal rate, time near singularity and torque error of a slew.

    Parameters
    ----------
    result : SimResult
        A run of :func:`airbearing.analysis.simulation.scenarios.slew`.
    settle_deg : float
        Pointing error (deg) within which the slew counts as settled.
    """
    m_ = result.model
    tb = m_.testbed
    dt = tb.sensors.dt
    t = np.append(result.t, result.t[-1] + dt)
    q = result.x[:, 0:4] if m_.dof == 3 else quat.from_yaw(result.x[:, 0])
    q_ref = np.vstack([result.reference[:, :4], result.reference[-1:, :4]])
    err = rotation_error_deg(q_ref, q)
    out = err > settle_deg
    settle = float(t[np.nonzero(out)[0][-1] + 1]) if out.any() and not out[-1] else None
    if not out.any():
        settle = 0.0
    d = result.x[:, m_.index(["d1", "d2", "d3", "d4"])]
    dd = result.u[:, m_.index(["dd1", "dd2", "dd3", "dd4"], "u")]
    beta = tb.cmg.skew
    mm = measure(d, beta)
    # torque error: wanted momentum rate -T_c - G x H (seed 001 eq. 11) against A dd (eq. 14)
    ex = dict(zip(result.controller.extra_names, result.extra.T, strict=True))
    Tc = np.stack([ex["Tc_x"], ex["Tc_y"], ex["Tc_z"]], 1)
    G = np.stack([ex["G_x"], ex["G_y"], ex["G_z"]], 1)
    Hn = _H_many(d[:-1], beta)
    want = -Tc - np.cross(G, Hn)
    A = _A_many(d[:-1], beta)
    got = np.einsum("nij,nj->ni", A, dd)
    if m_.dof == 1:
        want, got = want[:, 2:], got[:, 2:]
    h0 = tb.cmg.h0
    terr = np.linalg.norm(want - got, axis=1) * h0
    sing = singularity_summary(t, mm, threshold=NEAR_SINGULAR)
    w_idx = m_.index(["wx", "wy", "wz"] if m_.dof == 3 else ["wz"])
    return {
        "final_error_deg": float(err[-1]),
        "settle_time_s": settle if settle is not None else float("inf"),
        "peak_rate_deg_s": float(np.rad2deg(np.linalg.norm(result.x[:, w_idx], axis=1).max())),
        "peak_gimbal_rate_deg_s": float(np.rad2deg(np.abs(dd).max())),
        "peak_momentum_h0": float(np.linalg.norm(Hn, axis=1).max()),
        "max_torque_error_mNm": float(terr.max() * 1e3),
        **sing,
    }


def compare_slews(
    testbed: Testbed,
    *,
    laws=tuple(STEERING_LAWS),
    angle_deg: float = 180.0,
    axis=(0.0, 0.0, 1.0),
    duration: float = 30.0,
    ideal: bool = True,
    rate_limit_mode: str = "scale",
    steering_options: dict | None = None,
) -> tuple[list[dict], dict]:
    """The same slew with each law; returns the metric rows and the runs by law.

    Parameters
    ----------
    testbed : Testbed
        A ``kind = "cmg"`` testbed.
    laws : sequence of str
        Steering laws (:data:`airbearing.design.steering.STEERING_LAWS`).
    angle_deg : float
        Slew angle, deg.
    axis : sequence of 3 float
        Slew axis, body frame.
    duration : float
        Run length, s.
    ideal : bool
        No sensor noise, disturbance torque or gyro low-pass.
    rate_limit_mode : {"scale", "clip"}
        Seed 001 eq. 4 or per-gimbal clipping.
    steering_options : dict, optional
        Law name -> that law's options.

    Returns
    -------
    (list of dict, dict)
        One row of :func:`slew_metrics` per law (with ``law``: final error in deg, peak
        rates in deg/s, torque error in mN m ...), and the SimResult of each law.

    Examples
    --------
    >>> import airbearing as ab
    >>> rows, runs = ab.compare_slews(ab.load_testbed("cmg-yaw"), laws=("mp", "sr"),
    ...                               angle_deg=30.0, duration=5.0)
    >>> [(row["law"], round(row["final_error_deg"], 1)) for row in rows], sorted(runs)
    ([('mp', 0.9), ('sr', 0.9)], ['mp', 'sr'])
    """
    rows, runs = [], {}
    for law in laws:
        opts = (steering_options or {}).get(law)
        r = slew(
            testbed,
            angle_deg=angle_deg,
            axis=axis,
            duration=duration,
            ideal=ideal,
            steering=law,
            steering_options=opts,
            rate_limit_mode=rate_limit_mode,
        )
        runs[law] = r
        rows.append({"law": law, **slew_metrics(r)})
    return rows, runs


def rate_limit_comparison(
    testbed: Testbed,
    *,
    law: str = "mp",
    angle_deg: float = 90.0,
    axis=(1.0, 1.0, 1.0),
    duration: float = 20.0,
    max_gimbal_rate_deg: float | None = 20.0,
) -> tuple[list[dict], dict]:
    """Seed 001 eq. 4 (scale) against per-gimbal clipping, on the same slew.

    A lower rate limit than seed 001's (``max_gimbal_rate_deg``) makes the limiting act.
    Besides :func:`slew_metrics`, each row gives the largest angle (deg) between the
    delivered and the wanted momentum rate while the limit acts: zero for scaling
    (the direction is kept), not for clipping.

    Parameters
    ----------
    testbed : Testbed
        A ``kind = "cmg"`` testbed.
    law : str
        Steering law.
    angle_deg : float
        Slew angle, deg.
    axis : sequence of 3 float
        Slew axis, body frame (a dof-1 testbed turns about z only).
    duration : float
        Run length, s.
    max_gimbal_rate_deg : float or None
        Gimbal-rate limit of both runs, deg/s; None: the testbed's.

    Returns
    -------
    (list of dict, dict)
        One row per mode (``mode``, ``limit_active_s`` in s,
        ``max_torque_direction_error_deg`` in deg, and :func:`slew_metrics`), and the
        SimResult of each mode.

    Examples
    --------
    On the 3-axis CMG testbed, a 30 deg slew about (1, 1, 1) at 20 deg/s:

    >>> import airbearing as ab
    >>> rows, runs = ab.rate_limit_comparison(ab.load_testbed("cmg-3dof"), angle_deg=30.0,
    ...                                       duration=5.0)
    >>> [(row["mode"], round(row["max_torque_direction_error_deg"])) for row in rows]  # deg
    [('scale', 0), ('clip', 38)]
    """
    tb = testbed
    if max_gimbal_rate_deg is not None:
        tb = tb.replace(
            cmg=type(tb.cmg)(
                skew=tb.cmg.skew,
                flywheel_inertia=tb.cmg.flywheel_inertia,
                flywheel_speed=tb.cmg.flywheel_speed,
                max_gimbal_rate=np.deg2rad(max_gimbal_rate_deg),
                gimbal_angles=tb.cmg.gimbal_angles,
            )
        )
    rows, runs = [], {}
    for mode in ("scale", "clip"):
        r = slew(tb, angle_deg=angle_deg, axis=axis, duration=duration, ideal=True,
                 steering=law, rate_limit_mode=mode)  # fmt: skip
        runs[mode] = r
        met = slew_metrics(r)
        m_ = r.model
        d = r.x[:-1, m_.index(["d1", "d2", "d3", "d4"])]
        dd = r.u[:, m_.index(["dd1", "dd2", "dd3", "dd4"], "u")]
        ex = dict(zip(r.controller.extra_names, r.extra.T, strict=True))
        want = -np.stack([ex["Tc_x"], ex["Tc_y"], ex["Tc_z"]], 1) - np.cross(
            np.stack([ex["G_x"], ex["G_y"], ex["G_z"]], 1), _H_many(d, tb.cmg.skew)
        )
        got = np.einsum("nij,nj->ni", _A_many(d, tb.cmg.skew), dd)
        if m_.dof == 1:
            want, got = want[:, 2:], got[:, 2:]
        active = np.abs(dd).max(axis=1) >= tb.cmg.max_gimbal_rate * (1 - 1e-9)
        a = want / np.maximum(np.linalg.norm(want, axis=1, keepdims=True), 1e-300)
        b = got / np.maximum(np.linalg.norm(got, axis=1, keepdims=True), 1e-300)
        # angle between the two (Kahan's form, accurate near 0 where arccos is not)
        ang = np.rad2deg(
            2 * np.arctan2(np.linalg.norm(a - b, axis=1), np.linalg.norm(a + b, axis=1))
        )
        rows.append(
            {
                "mode": mode,
                "limit_active_s": float(active.sum() * tb.sensors.dt),
                "max_torque_direction_error_deg": float(ang[active].max()) if active.any() else 0.0,
                **met,
            }
        )
    return rows, runs
