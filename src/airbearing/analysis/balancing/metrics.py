"""Seed-000 metrics of a balancing run (Tables 1-2), the residual torque and kinetic energy.

Metrics (over the last third of the run, as the seed's "steady state")
    ``g_perp_rms``, ``g_x_rms``, ``g_y_rms``: RMS of the measured in-plane ``g_hat``
    components (what the seed's IMU measured; ``*_true`` from the true attitude);
    ``slider_p2p_m``, ``slider_std_m``: of the stepper positions (the step counts the seed
    logged; the mass positions, which include backlash, are in ``mass_p2p_m``);
    ``dipole_rms``: RMS of ``|d|``; ``residual_torque_nm``: seed 000's estimate, the
    left-hand side of seed 000 eq. 1 from the measured rates of the free-floating platform
    after balancing (sliders held, magnetorquers off), RMS over the free run;
    ``residual_offset_m``: the true CR -> CM offset the run leaves (simulation truth, the
    sliders where they end); ``residual_in_plane_torque_nm``: ``m |g|`` times its in-plane
    part, the gravity torque the method leaves (the free float's estimate is
    ``m |g| |r_z|`` times the swing's tilt from rest on top of it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.balancing.drift import window_drift
from airbearing.analysis.filters import savgol
from airbearing.analysis.simulation.simulate import SimResult
from airbearing.errors import InputError
from airbearing.io.testbed import Testbed

__all__ = [
    "SEED000_TABLES",
    "BalancingMetrics",
    "balancing_metrics",
    "inertia_with_sliders",
    "kinetic_energy",
    "last_third",
    "residual_torque",
    "true_offset",
]

#: s, Savitzky-Golay window of the rate derivative in the residual torque: 2 s averages the
#: gyro noise (about 40 samples at 20 Hz) and is short against the platform's swing periods.
_SG_WINDOW_S = 2.0

#: Seed 000 Tables 1 and 2 (averages of 4 tests each), SI units.
SEED000_TABLES = {
    -0.5e-3: {
        "mechanical": {"g_x_rms": 3.74e-3, "g_y_rms": 5.31e-3, "g_perp_rms": 6.49e-3,
                       "slider_p2p_m": (0.178e-3, 0.202e-3), "slider_std_m": (0.026e-3, 0.030e-3),
                       "residual_torque_nm": 8.3e-5},
        "mixed": {"g_x_rms": 2.15e-3, "g_y_rms": 1.54e-3, "g_perp_rms": 2.64e-3,
                  "slider_p2p_m": (0.014e-3, 0.010e-3), "slider_std_m": (0.004e-3, 0.002e-3),
                  "residual_torque_nm": 6.8e-5},
    },
    0.5e-3: {
        "mechanical": {"g_x_rms": 2.44e-3, "g_y_rms": 3.87e-3, "g_perp_rms": 4.57e-3,
                       "slider_p2p_m": (0.142e-3, 0.148e-3), "slider_std_m": (0.022e-3, 0.024e-3),
                       "residual_torque_nm": 7.9e-5},
        "mixed": {"g_x_rms": 1.54e-3, "g_y_rms": 2.71e-3, "g_perp_rms": 3.12e-3,
                  "slider_p2p_m": (0.020e-3, 0.012e-3), "slider_std_m": (0.004e-3, 0.004e-3),
                  "residual_torque_nm": 7.1e-5},
    },
}  # fmt: skip


def true_offset(testbed: Testbed, s, offset0) -> np.ndarray:
    """m, CR -> CM offset with the sliders at ``s`` (m), ``offset0`` with them at zero:
    ``offset0 + sum m_i s_i u_i / m`` (seed 004 eq. 5)."""
    m = testbed.masses
    moment = (np.asarray(m.mass_vec) * np.asarray(s, dtype=float)) @ np.asarray(m.axes_matrix)
    return np.asarray(offset0, dtype=float) + moment / testbed.body.mass


def last_third(a: np.ndarray) -> np.ndarray:
    n = a.shape[0]
    return a[n - max(1, n // 3) :]


def _rms(a, axis=None) -> np.ndarray:
    return np.sqrt(np.mean(np.square(a), axis=axis))


#: Keys of a run's context (:func:`~.runs.run_balancing`), after the measured ones.
_RUN_KEYS = (
    "method", "initial_offset_m", "seed", "vertical_offset_m", "start", "offset_stays",
    "duration_s", "residual_offset_m", "integral_time_constant_s", "settling_time_s",
    "residual_in_plane_torque_nm",
)  # fmt: skip


@dataclass(frozen=True, eq=False)
class BalancingMetrics(Mapping):
    """The seed-000 numbers of a balancing run (module notes), frozen.

    A read-only mapping over :meth:`to_json` (``metrics["g_perp_rms"]``, ``{**metrics}``),
    whose keys are the ``balance --json`` contract. The fields of a run's context
    (``method`` to ``settling_time_s``) are None for bare :func:`balancing_metrics` and
    are then left out of the JSON.

    Attributes
    ----------
    g_perp_rms, g_x_rms, g_y_rms, g_perp_rms_true : float
        RMS of the in-plane ``g_hat`` (measured; ``_true`` from the true attitude), -.
    slider_p2p_m, slider_std_m, mass_p2p_m, slider_final_m : tuple of float
        m, per slider.
    dipole_rms : float
        A m^2.
    residual_torque_nm : float or None
        N m, from the free float (None without one).
    residual_in_plane_torque_nm : float or None
        N m, ``m |g| |r_perp|`` of the in-plane offset the run leaves (simulation truth):
        the part of the residual torque the balancing method sets; the free float's
        estimate adds the vertical offset's pendulum torque of whatever swing it has.
    steady_check : dict
        :func:`~.drift.window_drift`'s keys (``metrics_window_s``, ``steady``, ...).
    note : str or None
        Why the run started level, or what the adaptive law cannot learn.
    """

    g_perp_rms: float
    g_x_rms: float
    g_y_rms: float
    g_perp_rms_true: float
    slider_p2p_m: tuple
    slider_std_m: tuple
    mass_p2p_m: tuple
    dipole_rms: float
    slider_final_m: tuple
    residual_torque_nm: float | None = None
    steady_check: dict = field(default_factory=dict, repr=False)
    note: str | None = field(default=None, repr=False)
    method: str | None = None
    initial_offset_m: float | None = None
    seed: int | None = None
    vertical_offset_m: float | None = None
    start: str | None = None
    offset_stays: bool | None = None
    duration_s: float | None = None
    residual_offset_m: tuple | None = field(default=None, repr=False)
    integral_time_constant_s: float | None = field(default=None, repr=False)
    settling_time_s: float | None = field(default=None, repr=False)
    residual_in_plane_torque_nm: float | None = field(default=None, repr=False)

    def to_json(self) -> dict:
        """The metrics as the ``balance --json`` keys (lists for the per-slider values)."""
        out = {
            "g_perp_rms": self.g_perp_rms,
            "g_x_rms": self.g_x_rms,
            "g_y_rms": self.g_y_rms,
            "g_perp_rms_true": self.g_perp_rms_true,
            "slider_p2p_m": list(self.slider_p2p_m),
            "slider_std_m": list(self.slider_std_m),
            "mass_p2p_m": list(self.mass_p2p_m),
            "dipole_rms": self.dipole_rms,
            "slider_final_m": list(self.slider_final_m),
            "residual_torque_nm": self.residual_torque_nm,
            **self.steady_check,
        }
        if self.note is not None:
            out["note"] = self.note
        if self.method is not None:
            for k in _RUN_KEYS:
                v = getattr(self, k)
                out[k] = list(v) if k == "residual_offset_m" else v
        return out

    def __getitem__(self, key):
        return self.to_json()[key]

    def __iter__(self):
        return iter(self.to_json())

    def __len__(self) -> int:
        return len(self.to_json())

    def __repr__(self) -> str:
        tail = f"method={self.method!r}, " if self.method is not None else ""
        return (
            f"BalancingMetrics({tail}g_perp_rms={self.g_perp_rms:.3g}, "
            f"dipole_rms={self.dipole_rms:.3g}, residual_torque_nm={self.residual_torque_nm}, "
            f"steady={self.steady_check.get('steady')})"
        )

    def __str__(self) -> str:
        p2p = ", ".join(f"{1e6 * v:.1f}" for v in self.slider_p2p_m)
        lines = [
            f"g_perp_rms {self.g_perp_rms:.3g} (x {self.g_x_rms:.3g}, y {self.g_y_rms:.3g})",
            f"slider p2p {p2p} um, dipole rms {self.dipole_rms:.3g} A m^2",
        ]
        if self.residual_torque_nm is not None:
            lines.append(f"residual torque {self.residual_torque_nm:.3g} N m")
        if self.steady_check.get("steady_reason"):
            lines.append(f"steady: {self.steady_check['steady_reason']}")
        if self.note:
            lines.append(f"note: {self.note}")
        return "\n".join(lines)


def balancing_metrics(result: SimResult, *, free: SimResult | None = None) -> BalancingMetrics:
    """The seed-000 numbers (Tables 1-2) of a balancing run, over its last third.

    Returns
    -------
    BalancingMetrics
        A mapping with ``g_perp_rms``, ``g_x_rms``, ``g_y_rms`` (-), ``g_perp_rms_true`` (-),
    ``slider_p2p_m``, ``slider_std_m``, ``mass_p2p_m`` (3 each, m), ``dipole_rms`` (A m^2),
    ``slider_final_m`` (3, m), ``residual_torque_nm`` (N m, None without ``free``), and
    the steady-state check of :func:`~.drift.window_drift` (``metrics_window_s``,
    ``steady``, ``steady_reason``, the two windows' ``g_perp_rms_windows``, ...).
    """
    m = result.model
    g = last_third(result.y[:, m.index(["gx", "gy", "gz"], "y")])
    q = last_third(result.x[:-1, 0:4])
    g_true = quat.rotate_inverse(q, np.array([0.0, 0.0, -1.0]))
    names = result.controller.extra_names
    motor = last_third(result.extra[:, [names.index(f"motor{i}") for i in (1, 2, 3)]])
    mass = last_third(result.u[:, m.index(["s1", "s2", "s3"], "u")])
    d = last_third(result.u[:, m.index(["mx", "my", "mz"], "u")])
    # is the metrics window steady? consecutive windows compared (.drift)
    g_all = result.y[:, m.index(["gx", "gy"], "y")]
    motor_all = result.extra[:, [names.index(f"motor{i}") for i in (1, 2)]]
    step = m.testbed.masses.step if m.testbed.masses is not None else 0.0
    return BalancingMetrics(
        g_perp_rms=float(_rms(np.hypot(g[:, 0], g[:, 1]))),
        g_x_rms=float(_rms(g[:, 0])),
        g_y_rms=float(_rms(g[:, 1])),
        g_perp_rms_true=float(_rms(np.hypot(g_true[:, 0], g_true[:, 1]))),
        slider_p2p_m=tuple(np.ptp(motor, axis=0).tolist()),
        slider_std_m=tuple(np.std(motor, axis=0).tolist()),
        mass_p2p_m=tuple(np.ptp(mass, axis=0).tolist()),
        dipole_rms=float(_rms(np.linalg.norm(d, axis=1))),
        slider_final_m=tuple(result.u[-1, m.index(["s1", "s2", "s3"], "u")].tolist()),
        residual_torque_nm=None if free is None else residual_torque(free),
        steady_check=window_drift(
            result.t, np.hypot(g_all[:, 0], g_all[:, 1]), motor_all, step=step
        ),
    )


def inertia_with_sliders(testbed: Testbed, s, inertia=None) -> np.ndarray:
    """Inertia about the CR (``inertia``, sliders at zero; default the testbed's nominal one)
    plus the sliders' point masses at ``s`` (seed 004 eqs. 6-7), kg m^2."""
    J = np.array(testbed.body.inertia_matrix if inertia is None else inertia, dtype=float)
    for u_i, m_i, s_i in zip(testbed.masses.axes_matrix, testbed.masses.mass_vec, s, strict=True):
        J += m_i * s_i**2 * (np.eye(3) - np.outer(u_i, u_i))
    return J


def residual_torque(free: SimResult, *, window_s: float = _SG_WINDOW_S) -> float:
    """Seed 000's residual-torque estimate from a free-floating run, N m.

    The left-hand side of seed 000 eq. 1, ``J w' + w x J w``, from the measured rates,
    with ``w'`` a Savitzky-Golay derivative (quadratic, ``window_s`` long) and ``J`` the
    nominal inertia with the sliders where they are; RMS of its norm over the run.
    """
    tb = free.model.testbed
    dt = tb.sensors.dt
    w = free.log.rates()
    n = int(round(window_s / dt)) | 1
    if w.shape[0] < n + 2:
        raise InputError(
            f"free-floating run of {w.shape[0]} samples is shorter than the {window_s} s "
            "derivative window"
        )
    w_dot = savgol(w, n, 2, deriv=1, delta=dt)
    w_s = savgol(w, n, 2)
    s = free.u[0, free.model.index(["s1", "s2", "s3"], "u")]
    J = inertia_with_sliders(tb, s)
    tau = w_dot @ J.T + np.cross(w_s, w_s @ J.T)  # seed 000 eq. 1, left-hand side
    half = n // 2
    return float(_rms(np.linalg.norm(tau[half:-half], axis=1)))


def kinetic_energy(w: np.ndarray, J: np.ndarray) -> np.ndarray:
    """Seed 004's ``E = w^T J w`` per sample (eq. 53 as the paper writes it), J.

    Twice the rotational kinetic energy ``(1/2) w^T J w``; the two-step's spreads are of
    this ``E``, so they compare with the paper's (ratios are the same for both).

    Parameters
    ----------
    w : (n, 3) array
        rad/s, body rates.
    J : (3, 3) array
        kg m^2, inertia about the centre of rotation.

    Returns
    -------
    (n,) array
        J, ``w_k^T J w_k``.
    """
    w = np.asarray(w, dtype=float)
    return np.einsum("ni,ij,nj->n", w, np.asarray(J, float), w)
