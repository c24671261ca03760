"""Words of the discrepancy workflow: values with errors, experiments that separate, verdicts."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from airbearing.analysis.discrepancy.trial import CandidateResult
    from airbearing.analysis.shooting import ShootingProblem

__all__ = [
    "EXPERIMENTS",
    "GENERIC_EXPERIMENT",
    "GYRO_BIAS_DOF1",
    "experiment_for",
    "format_value",
    "verdict",
    "why",
]

#: What separates two effects that fit the same data (name pair -> experiment).
EXPERIMENTS: dict[frozenset, str] = {
    frozenset({"cm_offset_error", "residual_dipole"}): (
        "under a vertical cage field a CM offset and a residual dipole give the same torque "
        "(m dr x g and m_res x b with b parallel to g); repeat the run with the cage field off "
        "or tilted: a CM-offset torque stays, a dipole torque vanishes or turns with the field"
    ),
    frozenset({"viscous_friction", "aero_drag"}): (
        "coast down from several initial rates: a viscous torque is proportional to w, "
        "aerodynamic drag to w^2, so their ratio changes with the speed (fit the logs together: "
        "airbearing discrepancy TESTBED LOG1 LOG2 ...)"
    ),
    frozenset({"viscous_friction", "coulomb_friction"}): (
        "coast down to rest: Coulomb friction gives a constant deceleration and a stop in "
        "finite time, viscous friction an exponential decay"
    ),
    frozenset({"coulomb_friction", "aero_drag"}): (
        "coast down from several initial rates: drag fades as w^2, Coulomb friction does not "
        "(fit the logs together: airbearing discrepancy TESTBED LOG1 LOG2 ...)"
    ),
    frozenset({"inertia_error", "gimbal_deadzone"}): (
        "command a slow ramp of the gimbal rates: a dead zone shows as no motion below the "
        "threshold, an inertia error scales every response"
    ),
    frozenset({"inertia_error", "sensor_lag"}): (
        "apply a torque step (sliders or gimbals): a lag delays the measured rate, an inertia "
        "error scales its slope"
    ),
    frozenset({"gyro_bias", "spring_torque"}): (
        "measure the yaw with an independent sensor (camera, encoder) during a long rest"
    ),
    frozenset({"yaw_imbalance", "spring_torque"}): (
        "spin through several turns: an imbalance torque repeats every turn, a spring's grows "
        "with the yaw turned (on a log that spans more than a turn a spring is not offered)"
    ),
    frozenset({"yaw_imbalance", "coulomb_friction"}): (
        "spin through several turns at two or more rates: the imbalance follows the yaw angle "
        "(once per turn, zero on average over a turn), Coulomb friction opposes the rate at "
        "every angle"
    ),
    frozenset({"yaw_imbalance", "viscous_friction"}): (
        "spin through several turns at two or more rates: the imbalance follows the yaw angle "
        "(once per turn), viscous friction the rate"
    ),
    frozenset({"yaw_imbalance", "aero_drag"}): (
        "spin through several turns at two or more rates: the imbalance follows the yaw angle "
        "(once per turn), drag the square of the rate"
    ),
}
GENERIC_EXPERIMENT = (
    "excite the testbed over a wider range of the states the two torques depend on "
    "(rates, attitude, inputs), so that their regressors stop being proportional"
)


def experiment_for(a: str, b: str) -> str:
    """The experiment that tells effect ``a`` from effect ``b``."""
    return EXPERIMENTS.get(frozenset((a, b)), GENERIC_EXPERIMENT)


def format_value(v, std=None) -> str:
    """An effect value (number or 3-vector) with its standard error, for text and reports."""
    if v is None:
        return "-"
    if isinstance(v, tuple | list | np.ndarray):
        s = "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
        if std is not None:
            s += " +- [" + ", ".join(f"{x:.2g}" for x in std) + "]"
        return s
    return f"{v:.4g}" + ("" if std is None else f" +- {std:.2g}")


def verdict(effects: dict, effect_std: dict, stop_reason: str) -> str:
    """One sentence: the named effects with their errors, or "no missing effect" and why."""
    if effects:
        parts = [f"{n} = {format_value(v, effect_std[n])}" for n, v in effects.items()]
        return "missing effect" + ("s" if len(effects) > 1 else "") + ": " + "; ".join(parts)
    return "no missing effect: " + (stop_reason or "nothing to add")


#: Why a gyro bias cannot be seen on a dof-1 testbed with a gyro (FORMATS.md: its ``yaw`` is
#: the testbed's own integral of the gyro, not an independent sensor; seed 001 Sec. 2.1.2).
GYRO_BIAS_DOF1 = (
    "a yaw-only testbed with a gyro logs the yaw as the integral of that gyro (FORMATS.md), "
    "so only the rate is compared, and a constant rate bias is exactly a different start "
    "rate of every window: no log of this testbed can show it (only an attitude measured "
    "independently of the gyro could)"
)


def why(problem: ShootingProblem, res: CandidateResult) -> CandidateResult:
    """A structural reason in place of the generic one where the physics says it."""
    if (
        res.name == "gyro_bias"
        and res.status == "not identifiable from this log"
        and problem.model.dof == 1
        and "yaw" not in problem.outputs
    ):
        return replace(res, reason=GYRO_BIAS_DOF1)
    return res
