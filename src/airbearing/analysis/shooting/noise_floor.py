"""The noise floor of logs, from the data alone: each output group's measurement noise,
the weights of the engine's fits (:class:`NoiseFloor`, :func:`noise_floor`).

Noise floor (from the data alone, per segment, outlier rows left out)
    The fourth DIVIDED difference on the logged times, with unit-norm weights
    (``sum c_j p(t_j) = 0`` for cubic ``p``, ``sum c_j^2 = 1``), removes a smooth
    motion to ``O(h^4)`` even on a jittered grid and passes white noise of standard
    deviation ``sigma`` unchanged; a median absolute deviation (times 1.4826) makes
    it robust. On a uniform grid it is the fourth difference divided by ``sqrt(70)``.
    Applied to the rates, to the yaw, to the wheel speeds, or (dof 3 without a gyro) to the rotation
    vectors of each 5-sample stencil from its first sample. A dof-3 attitude with a
    gyro: the body-frame increments ``2 vec(conj(q_k) (x) q_{k+1})`` minus the
    trapezoidal integral of the logged rate (var ``2 sa^2 + dt^2 sw^2 / 2``).
    The testbed's ``sensors.attitude_noise`` is reported beside it, not used.
    Wheel speeds (output ``ws``): a torque-commanded wheel's speed jumps in slope at every
    sample (``dW/dt = tau_m / Iw - a . dw/dt`` with the command held, FORMATS.md), by the
    command's own sample-to-sample noise divided by the small ``Iw``, which the fourth
    difference would take for measurement noise. The differences are taken of the
    wheel's absolute speed less the commanded torque's integral,
    ``A_k = W_k + a . w_k - sum_{j<k} dt_j tau_m(wc_j, W_j) / Iw`` (the simulator's motor
    torque, :func:`airbearing.models.wheels.motor_torque`: the command clipped at
    ``max_torque``, faded to none that would speed the wheel past ``max_speed``; with
    the testbed's known ``wheel_torque_error`` and ``wheel_inertia_error``), whose motion
    is only what the nominal model misses (friction, a torque error: slow), then the gyro's part
    ``|a|^2 sigma_rate^2`` is taken out of its variance; a speed-commanded wheel (its
    driver's loop follows the noisy speed) takes the fourth differences of ``W`` itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from airbearing import quaternion as quat
from airbearing.errors import InputError
from airbearing.models.wheels import motor_torque

if TYPE_CHECKING:
    from airbearing.analysis.shooting.logs import ReplayData

__all__ = [
    "ATTITUDE_SIGMA_MIN",
    "MAD_TO_SIGMA",
    "NOISE_DIFF_ORDER",
    "NoiseFloor",
    "RATE_SIGMA_MIN",
    "WS_SIGMA_MIN",
    "noise_floor",
]

#: Order of the difference that removes the smooth motion in :func:`noise_floor`.
NOISE_DIFF_ORDER = 4
#: 1 / Phi^-1(3/4): median absolute deviation -> standard deviation of a normal law.
MAD_TO_SIGMA = 1.482602218505602
#: rad/s and rad: smallest noise level used as a weight (a noise-free log stays well scaled).
RATE_SIGMA_MIN = 1e-7
ATTITUDE_SIGMA_MIN = 1e-6
#: rad/s: smallest wheel-speed noise level used as a weight (a part in 1e9 of a wheel's
#: hundreds of rad/s: the digits a log keeps).
WS_SIGMA_MIN = 1e-6


@dataclass(frozen=True)
class NoiseFloor:
    """White measurement noise estimated from the data alone.

    Attributes
    ----------
    rate_axes : ndarray or None
        rad/s, 1-sigma per free rate axis (None without a gyro).
    rate : float or None
        rad/s, RMS over the axes.
    attitude : float or None
        rad, 1-sigma attitude noise per axis (None for a dof-1 gyro log).
    gap_unit : str
        ``rad/s`` or ``rad``: the unit of :attr:`value`.
    testbed_attitude : float
        rad, the testbed's ``sensors.attitude_noise`` (0 when not given), for comparison.
    wheel_axes : ndarray or None
        rad/s, 1-sigma noise of each logged wheel speed (None without ``ws``).
    wheel : float or None
        rad/s, RMS over the wheels (None without ``ws``).
    """

    rate_axes: np.ndarray | None
    rate: float | None
    attitude: float | None
    gap_unit: str = "rad/s"
    testbed_attitude: float = 0.0
    wheel_axes: np.ndarray | None = None
    wheel: float | None = None

    @property
    def wheel_weight(self) -> float | None:
        """rad/s, the wheel speeds' weight: :attr:`wheel`, never below
        :data:`WS_SIGMA_MIN` (None without ``ws``)."""
        return None if self.wheel is None else max(self.wheel, WS_SIGMA_MIN)

    @property
    def wheel_weights(self) -> np.ndarray | None:
        """rad/s, each wheel speed's own weight: :attr:`wheel_axes`, never below
        :data:`WS_SIGMA_MIN` (None without ``ws``): a rig's tachometers need not be alike."""
        return None if self.wheel_axes is None else np.maximum(self.wheel_axes, WS_SIGMA_MIN)

    @property
    def measured(self) -> float:
        """The noise the data show, in :attr:`gap_unit`."""
        return float(self.rate if self.gap_unit == "rad/s" else self.attitude)

    @property
    def resolution(self) -> float:
        """The smallest noise level the replay weighs with, in :attr:`gap_unit`."""
        return RATE_SIGMA_MIN if self.gap_unit == "rad/s" else ATTITUDE_SIGMA_MIN

    @property
    def value(self) -> float:
        """The floor the gap is compared with, in :attr:`gap_unit`: the noise the data show,
        never below the replay's :attr:`resolution` (under it a noise-free log shows the
        integration's own error, not noise)."""
        return max(self.measured, self.resolution)

    @property
    def source(self) -> str:
        """How the floor was obtained, in words."""
        if self.measured < self.resolution:
            return (
                f"the replay's resolution: the data show {self.measured:.3g} {self.gap_unit} "
                "of noise, less than the integration's own error (a noise-free log)"
            )
        if self.gap_unit == "rad/s":
            return (
                "data: median absolute deviation of the unit-norm fourth divided differences "
                "of the logged rates (on the logged times)"
            )
        return (
            "data: median absolute deviation of the unit-norm fourth divided differences "
            "of the logged attitude (on the logged times)"
        )

    def to_json(self) -> dict:
        out = {
            "noise_floor": self.value,
            "gap_unit": self.gap_unit,
            "noise_floor_source": self.source,
            "rate_noise": self.rate,
            "attitude_noise": self.attitude,
            "testbed_attitude_noise": self.testbed_attitude or None,
        }
        if self.wheel is not None:
            out["wheel_speed_noise"] = self.wheel
        return out


def _pieces(d: ReplayData, k: int):
    """Row index arrays of differences of order ``k`` inside segments, no outlier touched."""
    out = []
    for a, b in d.segments:
        if b - a <= k:
            continue
        idx = np.arange(a, b - k)
        ok = np.ones(idx.size, dtype=bool)
        for j in range(k + 1):
            ok &= d.mask[idx + j]
        out.append(idx[ok])
    return np.concatenate(out) if out else np.zeros(0, dtype=int)


def _mad(d: np.ndarray) -> np.ndarray:
    med = np.median(d, axis=0)
    return MAD_TO_SIGMA * np.median(np.abs(d - med), axis=0)


def _weights(t: np.ndarray, idx: np.ndarray, k: int) -> np.ndarray:
    """Unit-norm divided-difference weights of order ``k`` on the logged times, (M, k + 1).

    ``sum_j c_j p(t_j) = 0`` for every polynomial of degree < ``k``, so a smooth motion
    cancels to ``O(h^k)`` on any (jittered) grid, and ``sum c_j^2 = 1`` makes white noise
    of standard deviation ``sigma`` come out with standard deviation ``sigma``. On a uniform
    grid this is the ``k``-th difference divided by ``sqrt(C(2k, k))`` (``sqrt(70)`` for 4).
    """
    T = t[idx[:, None] + np.arange(k + 1)[None, :]]
    T = (T - T[:, :1]) / np.maximum(T[:, -1:] - T[:, :1], 1e-300)
    c = np.ones_like(T)
    for j in range(k + 1):
        for i in range(k + 1):
            if i != j:
                c[:, j] /= T[:, j] - T[:, i]
    return c / np.linalg.norm(c, axis=1, keepdims=True)


def _diff_at(x: np.ndarray, t: np.ndarray, idx: np.ndarray, k: int) -> np.ndarray:
    """Normalised divided differences of ``x`` (N,) or (N, c) at stencils ``idx..idx+k``."""
    c = _weights(t, idx, k)
    x2 = x.reshape(len(x), -1)
    return sum(c[:, j : j + 1] * x2[idx + j] for j in range(k + 1))


def _attitude_diff(q: np.ndarray, t: np.ndarray, idx: np.ndarray, k: int) -> np.ndarray:
    """Divided differences of the attitude as rotation vectors from each stencil's first sample."""
    c = _weights(t, idx, k)
    q0c = quat.qconj(q[idx])
    out = np.zeros((idx.size, 3))
    for j in range(1, k + 1):
        out += c[:, j : j + 1] * quat.qlog(quat.qmul(q0c, q[idx + j]))
    return out


def _body_increments(q: np.ndarray) -> np.ndarray:
    inc = quat.qmul(quat.qconj(q[:-1]), q[1:])
    inc = inc * np.sign(inc[:, :1] + (inc[:, :1] == 0))
    return 2.0 * inc[:, 1:]


def noise_floor(datas) -> NoiseFloor:
    """Estimate the measurement noise of one or more logs from the data alone (module doc)."""
    datas = [datas] if hasattr(datas, "outputs") else list(datas)  # one ReplayData, or many
    d0 = datas[0]
    k = NOISE_DIFF_ORDER
    rate_axes = rate = att = None
    if d0.gyro:
        parts = [_diff_at(d.w, d.t, _pieces(d, k), k) for d in datas]
        D = np.concatenate(parts) if parts else np.zeros((0, d0.n_axes))
        if len(D) < 2:
            raise InputError(f"{d0.log.source}: too few consecutive usable rows for a noise floor")
        rate_axes = _mad(D)
        rate = float(np.sqrt(np.mean(rate_axes**2)))
    if d0.q is not None:
        if d0.gyro:
            es = []
            for d in datas:
                idx = _pieces(d, 1)
                inc = _body_increments(d.q)[idx]
                h = (d.t[idx + 1] - d.t[idx])[:, None]
                es.append(inc - 0.5 * (d.w[idx] + d.w[idx + 1]) * h)
            e = np.concatenate(es)
            s_e = float(np.sqrt(np.mean(_mad(e) ** 2)))
            var = (s_e**2 - 0.5 * d0.dt**2 * rate**2) / 2.0
            att = float(math.sqrt(max(var, 0.0)))
        else:
            es = [_attitude_diff(d.q, d.t, _pieces(d, k), k) for d in datas]
            att = float(np.sqrt(np.mean(_mad(np.concatenate(es)) ** 2)))
    elif not d0.gyro:
        parts = [_diff_at(d.att[:, 0], d.t, _pieces(d, k), k) for d in datas]
        att = float(_mad(np.concatenate(parts))[0])
    wheel_axes = wheel = None
    if d0.ws is not None:
        wheel_axes = _wheel_noise(datas, k, rate_axes)
        wheel = float(np.sqrt(np.mean(wheel_axes**2)))
    return NoiseFloor(
        rate_axes=rate_axes,
        rate=rate,
        attitude=att,
        gap_unit=d0.gap_unit,
        testbed_attitude=float(getattr(d0.testbed.sensors, "attitude_noise", 0.0) or 0.0),
        wheel_axes=wheel_axes,
        wheel=wheel,
    )


def _absolute_wheel_speed(d: ReplayData, a_rate: np.ndarray) -> np.ndarray:
    """``A_k`` of the module doc (N, n_wheels), rad/s, for a torque-commanded wheel: each
    segment's cumulative commanded speed change restarts at its first row."""
    wh = d.testbed.wheels
    wc = np.column_stack([d.input(f"wc{i}") for i in range(1, wh.n + 1)])
    # the testbed's known torque-constant and inertia errors (FORMATS.md effects), if any
    eff = d.testbed.effects
    gain = 1.0 + np.broadcast_to(np.asarray(eff.get("wheel_torque_error", 0.0), float), wh.n)
    inertia = wh.inertia_vec * (
        1.0 + np.broadcast_to(np.asarray(eff.get("wheel_inertia_error", 0.0), float), wh.n)
    )
    # the simulator's own motor torque (FORMATS.md [wheels]): clipped at max_torque, and
    # none that speeds the wheel past max_speed (a saturated wheel's command is not
    # integrated), evaluated at each sample's logged speed
    shape = wc.shape
    tau_m = motor_torque(ca.DM(wc), ca.DM(d.ws), ca.DM(np.broadcast_to(inertia, shape)),
                         ca.DM(np.broadcast_to(gain, shape)), mode="torque",
                         max_torque=wh.max_torque, max_speed=wh.max_speed,
                         speed_loop_tau=None)  # fmt: skip
    tau = np.asarray(tau_m, dtype=float).reshape(shape) / inertia[None, :]
    A = d.ws.copy()
    if d.w is not None:
        A += d.w @ a_rate.T
    step = np.r_[np.diff(d.t), 0.0][:, None] * tau
    for a, b in d.segments:
        A[a:b] -= np.r_[np.zeros((1, wh.n)), np.cumsum(step[a : b - 1], axis=0)]
    return A


def _wheel_noise(datas, k: int, rate_axes) -> np.ndarray:
    """rad/s, the noise of each logged wheel speed (module doc)."""
    d0 = datas[0]
    wh = d0.testbed.wheels
    axes = wh.axes_matrix
    a_rate = axes if d0.n_axes == 3 else axes[:, 2:3]
    torque = wh.command == "torque"
    parts = []
    for d in datas:
        x = _absolute_wheel_speed(d, a_rate) if torque else d.ws
        parts.append(_diff_at(x, d.t, _pieces(d, k), k))
    D = np.concatenate(parts) if parts else np.zeros((0, wh.n))
    if len(D) < 2:
        raise InputError(f"{d0.log.source}: too few consecutive usable rows for a noise floor")
    var = _mad(D) ** 2
    if torque and rate_axes is not None:
        # the gyro's noise in a . w (independent axes)
        var = var - (a_rate**2) @ (np.asarray(rate_axes) ** 2)
    return np.sqrt(np.maximum(var, 0.0))
