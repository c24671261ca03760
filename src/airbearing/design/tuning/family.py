"""The design family: the PID that places the design model's closed-loop poles at
``(s^2 + 2 zeta w s + w^2)(s + r w)``.

The per-axis design model (a pendulum ``J s^2 + k`` for balancing, a rigid body ``J s^2``
driven by ``h0`` times the command for the CMG loop, seed 001 eq. 19, or by the torque
itself on reaction wheels) closed by a PID
has a third-order characteristic polynomial, so ``(w, zeta, r)`` map one to one onto the
three gains (a balancing ``K_p`` that would be negative is clipped at 0).
"""

from __future__ import annotations

import numpy as np

from airbearing.design.linearise import linearisation
from airbearing.design.loops import Loop

__all__: list[str] = []


def _stiffness(loop: Loop) -> tuple[float, float]:
    """Balancing design model: the larger in-plane inertia J (kg m^2) and the smallest
    pendulum stiffness k (N m/rad, dw/dt = -(k/J) theta, torque m g r_z per radian)."""
    m, p = loop.model, loop.p
    A, _, _, _ = linearisation(m).matrices(loop.trim, p)
    Jd = np.array([p[m.index(n, "p")[0]] for n in ("J_xx", "J_yy")])
    return float(Jd.max()), float(min(-A[3, 0] * Jd[0], -A[4, 1] * Jd[1]))


def _family(loop: Loop, stiffness: float | None = None):
    """``gains(w, zeta, r)``: the PID placing the design model's poles at
    ``(s^2 + 2 zeta w s + w^2)(s + r w)`` (w in rad/s).

    ``stiffness``: the balancing design model's pendulum stiffness k, N m/rad (default
    ``loop``'s own). The tuner passes the softest corner's: every stiffer plant only adds
    to ``K_p + k``, so no ``K_p`` is clipped and every design stabilises the design model
    at every corner of the box, which spans a stiffness 75 times the softest by default
    (the offset before and after seed 004's step two).
    """
    m, p = loop.model, loop.p
    if loop.kind == "balancing":
        J, k = _stiffness(loop)
        k = k if stiffness is None else stiffness

        def gains(w, zeta, ratio):
            a = ratio * w
            return {
                "K_p": max(J * (w * w + 2 * zeta * w * a) - k, 0.0),
                "K_d": J * (2 * zeta * w + a),
                "K_dK_i": J * w * w * a,
            }

        return gains
    if loop.wheels:
        # torque = K_p q_v + K_i int q_v + K_w w in N m, q_v ~ theta / 2 (seed 001 eq. 19);
        # the design model the stiffest-to-turn axis (dof 3) or yaw (dof 1)
        axes = ("J_xx", "J_yy", "J_zz") if m.dof == 3 else ("J_zz",)
        Jw = max(float(p[m.index(n, "p")[0]]) for n in axes)

        def wheel_gains(w, zeta, ratio):
            a = ratio * w
            return {
                "K_p": 2 * Jw * (w * w + 2 * zeta * w * a),
                "K_i": 2 * Jw * w * w * a,
                "K_w": Jw * (2 * zeta * w + a),
            }

        return wheel_gains
    J = float(p[m.index("J_zz", "p")[0]])
    h0 = float(p[m.index("h0", "p")[0]])

    def gains(w, zeta, ratio):
        # torque = h0 (K_p q_v + K_i int q_v + K_w w), q_v ~ theta / 2 (seed 001 eqs. 19-20)
        a = ratio * w
        return {
            "K_p": 2 * J * (w * w + 2 * zeta * w * a) / h0,
            "K_i": 2 * J * w * w * a / h0,
            "K_w": J * (2 * zeta * w + a) / h0,
        }

    return gains
