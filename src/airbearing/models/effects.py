"""The effect registry: every named effect of FORMATS.md, with its parameters as CasADi symbols.

An effect is a small final object. While a Model is built it sees a
:class:`EffectContext` holding the symbolic plant quantities and may change:

* ``inertia_scale`` (inertia_error),
* ``gimbal_rates`` (gimbal_deadzone),
* ``torque`` (friction, drag, springs, the yaw imbalance, offsets, dipoles),
* ``rate_measured`` and ``lag`` states (gyro_bias, sensor_lag),
* the reaction wheels' ``wheel_friction`` (bearing torque ``tau_f``), ``wheel_gain`` (the
  motor's torque factor) and ``wheel_inertia_scale`` (the ``wheel_*`` effects).

A ``wheel_*`` effect has one parameter ``<name>`` for a number (every wheel) or one per
wheel, ``<name>_1 .. <name>_n``, for a list.

The discrepancy workflow walks :data:`REGISTRY`; a test checks that it names
exactly the vocabulary of FORMATS.md, so forgetting to register an effect fails.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca

from airbearing.errors import InputError
from airbearing.io.vocabulary import EFFECTS as VOCABULARY

__all__ = [
    "REGISTRY",
    "WHEEL_EFFECTS",
    "Effect",
    "EffectContext",
    "applicable_effects",
    "effect_param_names",
]

#: Rate within which Coulomb friction is smoothed to zero (FORMATS.md: "about 1e-3 rad/s").
COULOMB_SMOOTHING = 1e-3
#: Wheel speed within which a wheel's Coulomb friction is smoothed to zero, rad/s
#: (FORMATS.md: "about 0.1 rad/s"): ``f tanh(W / 0.1)``.
WHEEL_COULOMB_SMOOTHING = 0.1
#: The effects that act on reaction wheels (they need a ``[wheels]`` table).
WHEEL_EFFECTS = (
    "wheel_viscous_friction",
    "wheel_coulomb_friction",
    "wheel_torque_error",
    "wheel_inertia_error",
)
_AXES = "xyz"


@dataclass
class EffectContext:
    """Symbolic plant quantities an effect may read or change while a Model is built."""

    kind: str
    dof: int
    has_field: bool
    w: Any  # body rate (3,) for dof 3, (1,) = [wz] for dof 1
    yaw: Any = None  # dof 1 only
    g_body: Any = None  # (3,) gravity in body axes (dof 3)
    b_body: Any = None  # (3,) field in body axes
    mass: Any = None
    torque: Any = None  # same shape as w
    inertia_scale: Any = 1.0
    gimbal_rates: Any = None  # (4,) cmg only
    rate_measured: Any = None  # same shape as w
    lag_states: list = field(default_factory=list)  # (symbol, derivative, time constant)
    n_wheels: int = 0
    wheel_speeds: Any = None  # (n,) W, rad/s, relative to the body
    wheel_friction: Any = None  # (n,) bearing torque tau_f, N m (opposes W)
    wheel_gain: Any = None  # (n,) the motor gives gain x the requested torque
    wheel_inertia_scale: Any = None  # (n,) Iw_i is scale_i x Iw_i


@dataclass(frozen=True)
class Effect:
    """One named effect: how many parameters, where it applies, what it changes."""

    name: str
    stage: str  # "plant" (changes dynamics) or "sensor" (changes the measurement)

    def n_params(self, dof: int, per_axis: bool, n_wheels: int = 0) -> int:
        """Number of parameters; for a ``wheel_*`` effect ``per_axis`` means per wheel."""
        shape = VOCABULARY[self.name].shape
        if shape == "scalar_or_wheels":
            return n_wheels if per_axis and n_wheels else 1
        if shape == "vector3":
            return 3
        if shape == "pair":
            return 2
        if shape == "scalar_or_axes" and per_axis and dof == 3:
            return 3
        return 1

    def applies(
        self,
        kind: str,
        dof: int,
        has_field: bool,
        gyro: bool = True,
        wheel_command: str | None = None,
    ) -> str | None:
        """None when the effect can act on this testbed, else the reason it cannot.

        ``gyro`` is ``sensors.gyro``: without a rate sensor (attitude-only logs) the
        rate-sensor effects ``gyro_bias`` and ``sensor_lag`` have nothing to act on.
        ``wheel_command`` is ``wheels.command`` (``"torque"`` or ``"speed"``), or None for
        a testbed without reaction wheels: the ``wheel_*`` effects then have nothing to
        act on, and ``wheel_torque_error`` needs torque-commanded wheels.
        """
        if self.name in WHEEL_EFFECTS:
            if wheel_command is None:
                return f"{self.name} acts on reaction wheels, and this testbed has no [wheels]"
            if self.name == "wheel_torque_error" and wheel_command != "torque":
                return (
                    "wheel_torque_error scales a commanded motor torque; these wheels are "
                    "speed-commanded (wheels.command = 'speed'), their driver's loop hides it"
                )
            return None
        if self.stage == "sensor" and not gyro:
            return (
                f"{self.name} changes the measured rate, and this testbed has no rate sensor "
                "(sensors.gyro = false: attitude-only logs)"
            )
        if self.name == "spring_torque" and dof != 1:
            return "spring_torque acts on the yaw angle of a dof = 1 bearing"
        if self.name == "yaw_imbalance" and dof != 1:
            return (
                "yaw_imbalance is the once-per-turn gravity torque of a dof = 1 bearing whose "
                "axis is tilted; on a dof = 3 bearing the same physics is cm_offset_error"
            )
        if self.name == "cm_offset_error" and dof != 3:
            return "a CM offset gives no torque about the vertical axis of a dof = 1 bearing"
        if self.name == "residual_dipole" and not has_field:
            return "residual_dipole needs a magnetic field ([field] or bx, by, bz in the log)"
        if self.name == "gimbal_deadzone" and kind != "cmg":
            return "gimbal_deadzone needs a CMG cluster"
        return None

    def apply(self, ctx: EffectContext, theta) -> None:
        """Change ``ctx`` symbolically; ``theta`` holds this effect's parameters."""
        _APPLY[self.name](ctx, theta)


def _per_axis(ctx: EffectContext, theta):
    """Broadcast a 1- or 3-parameter vector onto the free axes of ``ctx.w``."""
    if ctx.dof == 1:
        return theta[theta.shape[0] - 1] if theta.shape[0] == 3 else theta[0]
    return theta if theta.shape[0] == 3 else ca.repmat(theta, 3, 1)


def _per_wheel(ctx: EffectContext, theta):
    """Broadcast a 1- or n-parameter vector onto the wheels."""
    n = ctx.n_wheels
    return theta if theta.shape[0] == n else ca.repmat(theta[0], n, 1)


def _wheel_viscous(ctx, th):
    ctx.wheel_friction = ctx.wheel_friction + _per_wheel(ctx, th) * ctx.wheel_speeds


def _wheel_coulomb(ctx, th):
    smooth = ca.tanh(ctx.wheel_speeds / WHEEL_COULOMB_SMOOTHING)
    ctx.wheel_friction = ctx.wheel_friction + _per_wheel(ctx, th) * smooth


def _wheel_torque_error(ctx, th):
    ctx.wheel_gain = ctx.wheel_gain * (1 + _per_wheel(ctx, th))


def _wheel_inertia_error(ctx, th):
    ctx.wheel_inertia_scale = ctx.wheel_inertia_scale * (1 + _per_wheel(ctx, th))


def _inertia_error(ctx, th):
    ctx.inertia_scale = ctx.inertia_scale * (1 + th[0])


def _viscous(ctx, th):
    ctx.torque = ctx.torque - _per_axis(ctx, th) * ctx.w


def _coulomb(ctx, th):
    ctx.torque = ctx.torque - _per_axis(ctx, th) * ca.tanh(ctx.w / COULOMB_SMOOTHING)


def _aero(ctx, th):
    ctx.torque = ctx.torque - _per_axis(ctx, th) * ca.fabs(ctx.w) * ctx.w


def _spring(ctx, th):
    ctx.torque = ctx.torque - th[0] * ctx.yaw


def _yaw_imbalance(ctx, th):
    # bearing axis tilted from vertical, CM off it: gravity torque once per turn
    ctx.torque = ctx.torque + th[0] * ca.sin(ctx.yaw) + th[1] * ca.cos(ctx.yaw)


def _cm_offset_error(ctx, th):
    ctx.torque = ctx.torque + ctx.mass * ca.cross(th, ctx.g_body)


def _residual_dipole(ctx, th):
    tau = ca.cross(th, ctx.b_body)
    ctx.torque = ctx.torque + (tau[2] if ctx.dof == 1 else tau)


def _gyro_bias(ctx, th):
    ctx.rate_measured = ctx.rate_measured + _per_axis(ctx, th)


def _sensor_lag(ctx, th):
    n = ctx.rate_measured.shape[0]
    lag = ca.SX.sym("w_lag", n)
    ctx.lag_states.append((lag, ctx.rate_measured, th[0]))
    ctx.rate_measured = lag


def _gimbal_deadzone(ctx, th):
    dd = ctx.gimbal_rates
    # commanded rates below the threshold give no motion (seed 001 Sec. 5: PWM dead zone)
    ctx.gimbal_rates = ca.if_else(ca.fabs(dd) > th[0], dd, 0 * dd)


_APPLY = {
    "inertia_error": _inertia_error,
    "viscous_friction": _viscous,
    "coulomb_friction": _coulomb,
    "aero_drag": _aero,
    "spring_torque": _spring,
    "yaw_imbalance": _yaw_imbalance,
    "cm_offset_error": _cm_offset_error,
    "residual_dipole": _residual_dipole,
    "gyro_bias": _gyro_bias,
    "sensor_lag": _sensor_lag,
    "gimbal_deadzone": _gimbal_deadzone,
    "wheel_viscous_friction": _wheel_viscous,
    "wheel_coulomb_friction": _wheel_coulomb,
    "wheel_torque_error": _wheel_torque_error,
    "wheel_inertia_error": _wheel_inertia_error,
}
_STAGE = {"gyro_bias": "sensor", "sensor_lag": "sensor"}

#: Every effect of FORMATS.md, by name, in the order of its table.
REGISTRY: dict[str, Effect] = {
    name: Effect(name, _STAGE.get(name, "plant")) for name in VOCABULARY if name in _APPLY
}


def get_effect(name: str) -> Effect:
    """The registered effect ``name``; an unknown name is an InputError listing the valid ones."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise InputError(
            f"unknown effect '{name}': expected one of {', '.join(REGISTRY)}"
        ) from None


def effect_param_names(name: str, dof: int, per_axis: bool, n_wheels: int = 0) -> list[str]:
    """Parameter names of effect ``name`` as they appear in a Model's ``p_names``.

    For a ``wheel_*`` effect ``per_axis`` means one parameter per wheel
    (``<name>_1 .. <name>_n``, ``n = n_wheels``); else one, ``<name>``.
    """
    n = get_effect(name).n_params(dof, per_axis, n_wheels)
    if name in WHEEL_EFFECTS:
        return [name] if not per_axis else [f"{name}_{i}" for i in range(1, n + 1)]
    if n == 2:  # a pair: yaw_imbalance's sine and cosine amplitudes
        return [f"{name}_s", f"{name}_c"]
    return [name] if n == 1 else [f"{name}_{a}" for a in _AXES]


def applicable_effects(
    kind: str, dof: int, has_field: bool, gyro: bool = True, wheel_command: str | None = None
) -> list[str]:
    """Names of the registered effects that can act on a testbed of this kind.

    Parameters
    ----------
    kind : {"platform", "cmg"}
    dof : {1, 3}
    has_field : bool
        A magnetic field acts (a ``[field]`` table, or a platform whose log may carry one).
    gyro : bool
        ``sensors.gyro``; False drops ``gyro_bias`` and ``sensor_lag`` (no rate sensor).
    wheel_command : {"torque", "speed"} or None
        ``wheels.command`` of a testbed with reaction wheels, None without: the
        ``wheel_*`` effects apply only with wheels.
    """
    return [
        n
        for n, e in REGISTRY.items()
        if e.applies(kind, dof, has_field, gyro, wheel_command) is None
    ]
