"""Words of the discrepancy workflow: values with errors, experiments that separate, verdicts."""

from __future__ import annotations

import math
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
    "WHEEL_INERTIA_UNSEEN",
    "experiment_for",
    "failure_words",
    "format_value",
    "verdict",
    "why",
]

#: What tells the air bearing's friction from a wheel bearing's.
_BEARINGS_APART = (
    "run with the wheels at a bias speed (a wheel then turns with the body for part of the "
    "log), or hold the body and let a wheel spin down with its motor off: the wheel "
    "bearing's friction slows the wheel, the air bearing's does not"
)
#: What separates two effects that fit the same data (name pair -> experiment).
EXPERIMENTS: dict[frozenset, str] = {
    frozenset({"cm_offset_error", "residual_dipole"}): (
        "under a vertical cage field a CM offset and a residual dipole give the same torque "
        "(m dr x g and m_res x b with b parallel to g); repeat the run with the cage field off, "
        "reversed or tilted (a CM-offset torque stays, a dipole torque vanishes, reverses or "
        "turns with the field), or move a slider by a known amount (the CM moves, the dipole "
        "does not)"
    ),
    frozenset({"cm_offset_error", "inertia_error"}): (
        "free motion fixes the inertia and the CM offset only up to a common scale (J w' + "
        "w x J w = m r x g is homogeneous in J and r); move a slider by a known amount "
        "between runs, or apply a known torque (a commanded dipole in the cage field, a "
        "reaction wheel), and fit the logs together"
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
    # reaction wheels: the body feels a wheel effect only through the reaction torque
    frozenset({"wheel_viscous_friction", "wheel_coulomb_friction"}): (
        "vary the wheel speed: a bias-speed change or a spin-down of the wheel (motor torque "
        "zero); viscous bearing friction follows the wheel speed, Coulomb friction stays the "
        "same at every speed of one sign"
    ),
    frozenset({"coulomb_friction", "wheel_coulomb_friction"}): (
        "a wheel that starts at rest turns against the body (momentum exchange), so the air "
        "bearing's friction and the wheel bearing's give one torque form on the body; "
        + _BEARINGS_APART
    ),
    frozenset({"viscous_friction", "wheel_viscous_friction"}): (
        "a wheel that starts at rest turns against the body at a rate proportional to the "
        "body's (momentum exchange), so the air bearing's viscous friction and the wheel "
        "bearing's give one torque form on the body; " + _BEARINGS_APART
    ),
    frozenset({"inertia_error", "wheel_torque_error"}): (
        "the body's rate sees the motor torque over J - Iw, so a larger body and a weaker motor "
        "give the same rate; apply a known external torque (a calibrated mass offset, a "
        "spring), or compare the wheel speeds' own slope with the command, the wheel's inertia "
        "known (a torque error changes it, a body inertia error does not)"
    ),
    frozenset({"inertia_error", "wheel_inertia_error"}): (
        "the body sees the wheel's inertia only through J - Iw (a part in a thousand of J); "
        "spin the wheel with the body held or with a known motor torque: the wheel speed's "
        "slope gives the wheel's inertia"
    ),
    frozenset({"wheel_torque_error", "wheel_inertia_error"}): (
        "momentum exchange fixes only the motor torque over the wheel's inertia; measure one "
        "of them on its own (the wheel's inertia on a torsion pendulum or from its data sheet, "
        "the motor torque from its current and torque constant)"
    ),
}
#: What separates the three scale effects (:data:`.confounding.SCALE_EFFECTS`).
SCALE_EXPERIMENT = (
    "only the wheels' motors act here, so scaling every inertia (the body's and the wheels') "
    "and every motor torque by one factor gives the same motion: a body inertia error e is "
    "a torque-constant error and a wheel inertia error of 1 / (1 + e) - 1 together; apply a "
    "known external torque (a calibrated mass offset, a spring, the magnetorquers in a known "
    "field), or measure one of the three on its own (the body's inertia with a known added "
    "inertia, the wheel's on a torsion pendulum, the motor torque from its current and "
    "torque constant)"
)
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


def _efficiency_words(eff) -> str:
    if eff is None:
        return ""
    e = np.atleast_1d(np.asarray(eff, dtype=float))
    if not np.all(np.isfinite(e)):
        return ""
    if e.size == 1:
        return f" (std / bound {e[0]:.2g})"
    return " (std / bound [" + ", ".join(f"{x:.2g}" for x in e) + "])"


#: IPOPT statuses in words (a candidate that did not converge says why, not the raw message).
SOLVER_WORDS = {
    "Maximum_Iterations_Exceeded": "IPOPT reached its iteration limit",
    "Restoration_Failed": "IPOPT's restoration phase failed",
    "Infeasible_Problem_Detected": "IPOPT found the bounds infeasible",
    "Error_In_Step_Computation": "IPOPT could not compute a step",
    "Invalid_Number_Detected": "the replay gave a non-finite number",
    "Maximum_CpuTime_Exceeded": "IPOPT ran out of time",
}


def failure_words(status: str, reason: str) -> str:
    """Why a candidate did not converge or sat at a bound, in a few words (no solver text)."""
    if status == "at its physical bound":
        head = reason.split(":")[0] if reason else ""
        return head.replace("pinned at its physical bound", "at its bound") or "at its bound"
    for key, words in SOLVER_WORDS.items():
        if key in reason:
            return words
    if "not finite" in reason:
        return "the replay is not finite" + (
            " at the start" if "starting point" in reason else " at the fit"
        )
    if "gimbal motion" in reason:
        return "the log commands no gimbal motion"
    return "the fit did not converge"


def verdict(
    effects: dict,
    effect_std: dict,
    stop_reason: str,
    *,
    efficiency: dict | None = None,
    adequacy=None,
    unfit=(),
    disagreements=(),
    nominal: dict | None = None,
    confounding=(),
) -> str:
    """The verdict: named effects with errors and efficiency, or what the model leaves.

    Parameters
    ----------
    effects, effect_std : dict
        Named effects and their (honest) 1-sigma.
    stop_reason : str
        Why the search stopped.
    efficiency : dict, optional
        ``name -> std / Cramer-Rao bound``.
    adequacy : Adequacy, optional
        The final fit's adequacy (:mod:`.adequacy`): "no missing effect: the nominal model
        explains the data" is said only when its residual is at the noise.
    unfit : sequence of (label, words)
        Candidates that did not converge or sat at a bound, and why.
    disagreements : sequence of str
        Effects the runs disagree on, in words.
    nominal : dict, optional
        ``name -> nominal value`` of the named effects that correct the testbed's own
        (their ``effects`` value is the total).
    confounding : sequence of Confounding
        What the logs cannot tell apart (:mod:`.confounding`): a named effect and another
        effect of one torque form (named together, neither preferred), or a named effect
        and a constant torque about a steady axis; each with the experiment that separates
        them.
    """
    efficiency, nominal = efficiency or {}, nominal or {}
    twins: dict = {}
    for c in confounding:
        if c.equivalent and _head(c) in effects:
            twins.setdefault(_head(c), []).append(c)
    remains = adequacy is not None and adequacy.structure_remains
    if effects:
        parts = [
            f"{n} = {format_value(v, effect_std[n])}"
            + (f" (nominal {format_value(nominal[n])})" if n in nominal else "")
            + _efficiency_words(efficiency.get(n))
            + "".join(_twin_words(c) for c in twins.get(n, ()))
            for n, v in effects.items()
        ]
        what = "corrected effect" if set(effects) <= set(nominal) else "missing effect"
        text = what + ("s" if len(effects) > 1 else "") + ": " + "; ".join(parts)
        for c in confounding:
            if _head(c) in effects:
                text += "; " + _separate_words(c)
        if remains:
            text += "; " + adequacy.words(named=True)
    elif not remains:
        std_reasons = ("", "no candidate may be named")
        text = "no missing effect: the nominal model explains the data"
        if adequacy is None:
            text = "no missing effect: " + (stop_reason or "nothing to add")
        elif stop_reason not in std_reasons:
            text += f" ({stop_reason})"
    else:
        n = adequacy.gap_over_floor
        if stop_reason.startswith("max_effects = 0"):
            text = (
                "no effect searched (max_effects = 0): the nominal model leaves "
                f"{n:.3g} x the noise floor"
            )
        else:
            text = (
                "no candidate of the vocabulary explains the remaining gap "
                f"({n:.3g} x the noise floor)"
            )
        text += "; " + adequacy.words(named=False)
    if unfit:
        text += "; not converged or at a bound: " + ", ".join(f"{c} ({w})" for c, w in unfit)
    for d in disagreements:
        text += "; " + d
    return text


def _head(c) -> str:
    """The named effect a confounding belongs to (the first of several named together)."""
    return c.effects[0].split(" + ")[0]


def _twin_words(c) -> str:
    """`` or, equally, b = value (...)`` after a named effect ``a`` the logs cannot tell
    from ``b``."""
    b = c.effects[1]
    sine = math.sqrt(max(1.0 - c.correlation**2, 0.0))
    value = " with ".join(f"{n} = {format_value(v)}" for n, v in c.equivalent.items())
    how = (
        "one torque form on these logs"
        if c.kind == "exact"
        else (f"one torque form on these logs to {sine:.1g} of a torque")
    )
    if b not in c.equivalent:  # several effects together make the named one's torque
        return f" OR, equally, {value} ({how}: neither is preferred)"
    return f" OR, equally, {b} = {format_value(c.equivalent[b])} ({how}: neither is preferred)"


def _separate_words(c) -> str:
    """What separates a confounded pair, in words."""
    a, b = c.effects
    if not c.equivalent:  # a constant torque about a steady axis
        verb = "cannot be told" if c.kind == "exact" else "can hardly be told"
        return f"{a} {verb} from a {b} on these logs: {c.experiment}"
    return f"to tell {a} from {b}: {c.experiment}"


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
    if (
        res.name == "wheel_inertia_error"
        and res.status == "at its physical bound"
        and "ws" not in problem.outputs
    ):
        head, colon, rest = (res.reason or "").partition(":")
        return replace(res, reason=f"{head} ({WHEEL_INERTIA_UNSEEN})" + colon + rest)
    return res


#: Why a wheel's inertia error sits at a bound rather than at its value when the wheel
#: speeds are not compared: the body sees the wheel's inertia only through ``J - Iw`` (the
#: wheel's own acceleration is in the wheel speeds, which then only start each window).
WHEEL_INERTIA_UNSEEN = (
    "the body sees a wheel's inertia only through J - Iw, and the wheel speeds are not fitted"
)
