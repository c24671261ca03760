"""The balancing loop's gains: the seed-000 PID's (:class:`BalancingGains`), the defaults of
the Lyapunov and adaptive laws matched to it, the PID gains that place the tilt loop's poles
(:func:`tilt_pid_gains`) and the Lyapunov gains equivalent to a PID
(:func:`lyapunov_gains_from_pid`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from airbearing.errors import InputError

__all__ = [
    "ADAPTIVE_DEFAULT_GAINS",
    "BalancingGains",
    "LYAPUNOV_DEFAULT_GAINS",
    "SEED000_GAINS",
    "TILT_INTEGRAL_RATE",
    "lyapunov_gains_from_pid",
    "tilt_pid_gains",
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
